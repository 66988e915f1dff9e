// The translucent vessel: Lambert under a headlight, more opaque where the wall is seen edge
// on, so the outline of the lumen reads clearly while the rods inside stay visible. Drawn after
// the opaque rods, depth-tested against them but not writing depth, faces turned away from the
// camera culled (the wall nearer the camera, for a mesh whose normals point into the lumen).

struct Camera {
    view_projection: mat4x4<f32>,
    // xyz: unit vector from the scene towards the camera (orthographic light direction).
    towards_camera: vec4<f32>,
    // xyz: the eye; w = 1 for a perspective camera, 0 for an orthographic one.
    eye: vec4<f32>,
}

@group(0) @binding(0) var<uniform> camera: Camera;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) colour: vec4<f32>,
}

@vertex
fn vs_main(
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) colour: vec4<f32>,
) -> VertexOut {
    var out: VertexOut;
    out.clip = camera.view_projection * vec4<f32>(position, 1.0);
    out.world = position;
    out.normal = normal;
    out.colour = colour;
    return out;
}

fn light_direction(world: vec3<f32>) -> vec3<f32> {
    if camera.eye.w > 0.5 {
        return normalize(camera.eye.xyz - world);
    }
    return camera.towards_camera.xyz;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    let facing = abs(dot(n, light_direction(in.world)));
    let rgb = in.colour.rgb * (0.45 + 0.55 * facing);
    let alpha = clamp(in.colour.a * (1.0 + 1.5 * (1.0 - facing)), 0.0, 1.0);
    return vec4<f32>(rgb, alpha);
}
