// Opaque rods: Blinn–Phong under a headlight (the light sits at the camera, so nothing the
// camera sees is in shadow and the picture needs no light to be placed).

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
    let l = light_direction(in.world);
    let diffuse = max(dot(n, l), 0.0);
    // With the light at the eye the half vector is the light direction itself.
    let specular = pow(diffuse, 48.0);
    let rgb = in.colour.rgb * (0.22 + 0.78 * diffuse) + vec3<f32>(0.15 * specular);
    return vec4<f32>(rgb, 1.0);
}
