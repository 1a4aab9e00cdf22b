// An opaque image copied pixel for pixel into the viewport: one triangle over the viewport,
// one texel fetch per pixel, no filtering and no blending. On a CPU Vulkan driver this costs
// a fraction of a filtered, blended textured quad.

@group(0) @binding(0) var image: texture_2d<f32>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    // Texel coordinates: the pixel centre k + 0.5 of the viewport lands in texel k.
    @location(0) @interpolate(linear) texel: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VertexOut {
    // (0, 0), (2, 0), (0, 2) in fractions of the viewport: covers it once.
    let f = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: VertexOut;
    out.clip = vec4<f32>(f.x * 2.0 - 1.0, 1.0 - f.y * 2.0, 0.0, 1.0);
    out.texel = f * vec2<f32>(textureDimensions(image));
    return out;
}

@fragment
fn fs_main(v: VertexOut) -> @location(0) vec4<f32> {
    let last = vec2<i32>(textureDimensions(image)) - vec2<i32>(1, 1);
    return textureLoad(image, clamp(vec2<i32>(v.texel), vec2<i32>(0, 0), last), 0);
}
