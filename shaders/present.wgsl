// The shaded image (one packed RGBA8 word per pixel, sRGB-encoded bytes, as shade.wgsl and
// water.wgsl write it) copied into an Rgba8Unorm texture that a window toolkit can draw
// (egui-wgpu's register_native_texture). The bytes are kept as they are: the texture holds
// exactly the pixels a PNG of the frame holds.

@group(0) @binding(101) var frame_texture: texture_storage_2d<rgba8unorm, write>;

@compute @workgroup_size(8, 8, 1)
fn present(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(frame_texture);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let word = image_at(gid.y * size.x + gid.x);
    textureStore(frame_texture, vec2<i32>(gid.xy), unpack4x8unorm(word));
}
