// Shared quaternion, Darboux-vector and energy-gradient helpers: the WGSL twins of
// `cosserat_model::{quat, darboux, energy}`. Every kernel is composed as this module followed by
// the kernel's own text, so there is one definition of the physics on the GPU as on the CPU.
//
// Conventions (crates/cosserat-model/src/lib.rs): quaternions are vec4(x, y, z, w) and map body
// to world; torques and angular velocities are in body coordinates; the Darboux vector of node j
// lies in the body frame of frame j.

// Hamilton product a ⊗ b.
fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(
        a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz),
        a.w * b.w - dot(a.xyz, b.xyz),
    );
}

// Rotates the body vector v into world coordinates: v + 2w(u×v) + 2u×(u×v).
fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = cross(q.xyz, v) * 2.0;
    return v + t * q.w + cross(q.xyz, t);
}

// Rotates the world vector v into body coordinates (inverse of quat_rotate).
// The homogeneous form (v (w² − |u|²) + 2 u (u·v) + 2 w u × v): for a quaternion normalised in
// f32 it is a rotation scaled by |q|², so the small components the parallel penalty reads stay
// small (cosserat_model::quat::directors says what the other form cost).
fn quat_rotate_inv(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let u = -q.xyz;
    return v * (q.w * q.w - dot(u, u)) + u * (2.0 * dot(u, v)) + cross(u, v) * (2.0 * q.w);
}

// The third director d3 = q e3 q̄.
fn quat_d3(q: vec4<f32>) -> vec3<f32> {
    return vec3<f32>(
        2.0 * (q.x * q.z + q.w * q.y),
        2.0 * (q.y * q.z - q.w * q.x),
        q.w * q.w - q.x * q.x - q.y * q.y + q.z * q.z,
    );
}

// q̄_a q_b with the sign chosen so that its real part is >= 0 (the short way round).
fn relative_rotation(qa: vec4<f32>, qb: vec4<f32>) -> vec4<f32> {
    let s = quat_mul(vec4<f32>(-qa.xyz, qa.w), qb);
    return select(s, -s, s.w < 0.0);
}

// Discrete Darboux vector (2/l) Im(q̄_a q_b) in the body frame of qa.
fn darboux(qa: vec4<f32>, qb: vec4<f32>, l: f32) -> vec3<f32> {
    return relative_rotation(qa, qb).xyz * (2.0 / l);
}

// Body-frame torques of the bending/twisting energy at one node on its two frames
// (energy::bend_twist_node).
struct NodeTorques {
    ta: vec3<f32>,
    tb: vec3<f32>,
}

fn bend_twist_node(qa: vec4<f32>, qb: vec4<f32>, rest: vec3<f32>, k: vec3<f32>, l: f32) -> NodeTorques {
    let s = relative_rotation(qa, qb);
    let delta = s.xyz * (2.0 / l) - rest;
    let f = k * delta;
    let svxf = cross(s.xyz, f);
    let fw = f * s.w;
    return NodeTorques(fw + svxf, svxf - fw);
}

// Parallel-constraint penalty of one element (energy::parallel_element): the force on r_b (its
// negative acts on r_a) and the body-frame torque on q.
struct ElementForce {
    fb: vec3<f32>,
    torque: vec3<f32>,
}

fn parallel_element(ra: vec3<f32>, rb: vec3<f32>, q: vec4<f32>, kp: f32, l0: f32) -> ElementForce {
    let e = rb - ra;
    let len = length(e);
    let t = e / len;
    let d = quat_d3(q);
    let c = kp * l0;
    let fb = (d - t * dot(t, d)) * (c / len);
    let tb = quat_rotate_inv(q, t);
    return ElementForce(fb, vec3<f32>(-tb.y, tb.x, 0.0) * c);
}

// Stretching force on r_b (energy::stretch_element), extensible mode only.
fn stretch_element(ra: vec3<f32>, rb: vec3<f32>, ks: f32, l0: f32) -> vec3<f32> {
    let e = rb - ra;
    let len = length(e);
    let strain = len / l0 - 1.0;
    return e * (-ks * strain / len);
}

// Dissipation force on r_b from the stretching rate (energy::stretch_damping_element).
fn stretch_damping_element(ra: vec3<f32>, rb: vec3<f32>, va: vec3<f32>, vb: vec3<f32>, c: f32, l0: f32) -> vec3<f32> {
    let e = rb - ra;
    let len2 = dot(e, e);
    return e * (-c * dot(e, vb - va) / (l0 * len2));
}

// Dissipation torques from the relative angular velocity of two frames (energy::bend_damping_node).
fn bend_damping_node(qa: vec4<f32>, qb: vec4<f32>, wa: vec3<f32>, wb: vec3<f32>, c: f32, l: f32) -> NodeTorques {
    let rel = quat_rotate(qb, wb) - quat_rotate(qa, wa);
    let tw = rel * (c / l);
    return NodeTorques(quat_rotate_inv(qa, tw), -quat_rotate_inv(qb, tw));
}

// The unit quaternion of the rotation vector v (quat::exp_rotation). Below 0.1 rad the sine
// and cosine come from their series, which are exact in f32 there: a GPU's sin and cos are
// accurate only absolutely (WGSL allows 2^-11), and sin(|v|/2)/|v| for the small turn of one
// step would carry that error as a relative one.
fn exp_rotation(v: vec3<f32>) -> vec4<f32> {
    let angle = length(v);
    let half = angle * 0.5;
    var s: f32;
    var c: f32;
    if angle < 0.1 {
        let a2 = angle * angle;
        s = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0;
        c = 1.0 - a2 / 8.0 + a2 * a2 / 384.0;
    } else {
        s = sin(half) / angle;
        c = cos(half);
    }
    return vec4<f32>(v * s, c);
}

// Body torque a clamp gives the rod's end frame q (body angular velocity w) through its
// bend–twist node (energy::clamp_node, energy::clamp_damping; the CPU's clamp_torque): the node
// runs from the clamp frame qc to q at the first end, from q to qc at the last (`last`). The
// clamp turns at the world angular velocity om; damping only where c > 0.
fn clamp_torque(qc: vec4<f32>, q: vec4<f32>, w: vec3<f32>, om: vec3<f32>, rest: vec3<f32>, k: vec3<f32>, l: f32, c: f32, last: bool) -> vec3<f32> {
    var t: vec3<f32>;
    if last {
        t = bend_twist_node(q, qc, rest, k, l).ta;
    } else {
        t = bend_twist_node(qc, q, rest, k, l).tb;
    }
    if c > 0.0 {
        t += bend_damping_node(qc, q, quat_rotate_inv(qc, om), w, c, l).tb;
    }
    return t;
}

// True when x is NaN or infinite. WGSL has no isnan/isinf, and comparisons with NaN may be
// folded away by a driver that assumes finite math, so look at the exponent bits.
fn not_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) == 0x7f800000u;
}
