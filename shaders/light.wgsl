// Lighting shared by the shade pass and the water pass (appended before either): sRGB
// packing, the background, and a light rig that reads well on fluids.

// The key light is `settings.key_light`: a unit direction in the cache's local coordinates
// (world directions: the local frame is only shifted and scaled), set per frame.

fn srgb(v: f32) -> f32 {
    let c = clamp(v, 0.0, 1.0);
    return select(1.055 * pow(c, 1.0 / 2.4) - 0.055, 12.92 * c, c <= 0.0031308);
}

fn pack(rgb: vec3<f32>) -> u32 {
    let c = vec3<u32>(round(vec3<f32>(srgb(rgb.x), srgb(rgb.y), srgb(rgb.z)) * 255.0));
    return c.x | (c.y << 8u) | (c.z << 16u) | (255u << 24u);
}

fn background(y: u32) -> vec3<f32> {
    let t = f32(y) / f32(settings.height);
    return vec3<f32>(0.03 + 0.05 * t, 0.035 + 0.05 * t, 0.05 + 0.06 * t);
}

fn blinn_phong(n_in: vec3<f32>, dir: vec3<f32>, base: vec3<f32>) -> vec3<f32> {
    let n = select(n_in, -n_in, dot(n_in, dir) > 0.0);
    let view = -dir;
    let key = settings.key_light;
    let fill = normalize(vec3<f32>(-0.6, 0.5, 0.3));
    let half_vector = normalize(key + view);
    let diffuse = 0.85 * max(dot(n, key), 0.0) + 0.25 * max(dot(n, fill), 0.0);
    let spec = 0.6 * pow(max(dot(n, half_vector), 0.0), 60.0);
    // A rim term reads the silhouette of thin sheets against the background.
    let rim = 0.25 * pow(1.0 - max(dot(n, view), 0.0), 3.0);
    return base * (0.12 + diffuse) + vec3<f32>(spec + rim);
}

