// Endoscopic view: one light at the camera, lit per vertex (Gouraud) like the CPU reference
// renderer. The vertex stage is voyage_view::Lighting::linear and the
// display gamma, term for term; the fragment stage writes the interpolated colour, so the
// GPU image equals the CPU one within rounding.

struct Uniforms {
    // proj · view · translate(eye): clip position of an eye-relative point.
    eye_relative_to_clip: mat4x4<f32>,
    eye: vec4<f32>,
    // albedo (linear RGB) in xyz, ambient in w.
    albedo_ambient: vec4<f32>,
    // falloff_mm, specular, shininess, unused.
    light: vec4<f32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    // Display colour (gamma applied), interpolated perspective-correctly.
    @location(0) color: vec3<f32>,
};

// pow(x, y) for x ≥ 0 with pow(0, y) = 0 (WGSL leaves pow(0, y) to the implementation).
fn pow0(x: f32, y: f32) -> f32 {
    return select(0.0, pow(x, y), x > 0.0);
}

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    // P − eye in mm: no cancellation of two ~500 mm values.
    let rel = v.position - u.eye.xyz;
    out.clip = u.eye_relative_to_clip * vec4<f32>(rel, 1.0);
    let d = length(rel);
    // L = (eye − P) / d.
    let l = -rel / max(d, 1e-12);
    let n = normalize(v.normal);
    let ndl = clamp(dot(n, l), 0.0, 1.0);
    let albedo = u.albedo_ambient.xyz;
    let ambient = u.albedo_ambient.w;
    let falloff = u.light.x;
    let specular = u.light.y;
    let shininess = u.light.z;
    let r = d / falloff;
    let att = 1.0 / (1.0 + r * r);
    let diffuse = ambient + (1.0 - ambient) * ndl * att;
    let spec = specular * pow0(ndl, shininess) * att;
    let lin = clamp(albedo * diffuse + vec3<f32>(spec), vec3<f32>(0.0), vec3<f32>(1.0));
    let g = 1.0 / 2.2;
    out.color = vec3<f32>(pow0(lin.x, g), pow0(lin.y, g), pow0(lin.z, g));
    return out;
}

@fragment
fn fs_main(f: VertexOut) -> @location(0) vec4<f32> {
    // A plain Unorm target: the hardware's float → 8-bit conversion rounds like the CPU's
    // + 0.5.
    return vec4<f32>(f.color, 1.0);
}
