// Endoscopic view: one light at the camera. The fragment stage is
// voyage_core::render::shading::Lighting::linear and encode(), term for term, so that the
// GPU image equals the CPU reference renderer's within rounding.

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
    // P − eye in mm, interpolated perspective-correctly: the fragment's world position
    // relative to the camera, without the cancellation of subtracting two ~500 mm values
    // per fragment.
    @location(0) rel: vec3<f32>,
    @location(1) normal: vec3<f32>,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    let rel = v.position - u.eye.xyz;
    out.clip = u.eye_relative_to_clip * vec4<f32>(rel, 1.0);
    out.rel = rel;
    out.normal = v.normal;
    return out;
}

// pow(x, y) for x ≥ 0 with pow(0, y) = 0 (WGSL leaves pow(0, y) to the implementation).
fn pow0(x: f32, y: f32) -> f32 {
    return select(0.0, pow(x, y), x > 0.0);
}

@fragment
fn fs_main(f: VertexOut) -> @location(0) vec4<f32> {
    let d = length(f.rel);
    // L = (eye − P) / d.
    let l = -f.rel / max(d, 1e-12);
    let n = normalize(f.normal);
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
    // Display gamma 2.2 into a plain Unorm target: the hardware's float → 8-bit conversion
    // rounds like encode()'s + 0.5.
    let g = 1.0 / 2.2;
    return vec4<f32>(pow0(lin.x, g), pow0(lin.y, g), pow0(lin.z, g), 1.0);
}
