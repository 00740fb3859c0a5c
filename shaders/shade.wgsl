// The shade pass: one thread per pixel, from the hit buffer to an sRGB pixel. Modes (mirrors
// `slosh_render::ShadeMode`): 0 shade (Blinn–Phong under a key, a fill and a rim light;
// coloured by a scalar field when one is bound), 1 normals, 2 status and iteration heat map,
// 3 back faces flagged. Appended to mls.wgsl.

@group(0) @binding(5) var<storage, read> balls: array<Ball>;
@group(0) @binding(9) var<storage, read> field: array<f32>;
@group(1) @binding(0) var<storage, read_write> hits: array<Hit>;
@group(1) @binding(1) var<storage, read_write> image: array<u32>;

const MODE_SHADE: u32 = 0u;
const MODE_NORMALS: u32 = 1u;
const MODE_STATUS: u32 = 2u;
const MODE_BACKFACES: u32 = 3u;

fn srgb(v: f32) -> f32 {
    let c = clamp(v, 0.0, 1.0);
    return select(1.055 * pow(c, 1.0 / 2.4) - 0.055, 12.92 * c, c <= 0.0031308);
}

fn pack(rgb: vec3<f32>) -> u32 {
    let c = vec3<u32>(round(vec3<f32>(srgb(rgb.x), srgb(rgb.y), srgb(rgb.z)) * 255.0));
    return c.x | (c.y << 8u) | (c.z << 16u) | (255u << 24u);
}

// Viridis (perceptually uniform), a degree-6 fit of the matplotlib table; t in [0, 1].
fn viridis(t_in: f32) -> vec3<f32> {
    let t = clamp(t_in, 0.0, 1.0);
    let c0 = vec3<f32>(0.2777273, 0.0054073, 0.3340998);
    let c1 = vec3<f32>(0.1050930, 1.4046135, 1.3845901);
    let c2 = vec3<f32>(-0.3308618, 0.2148476, 0.0950952);
    let c3 = vec3<f32>(-4.6342305, -5.7991009, -19.3324410);
    let c4 = vec3<f32>(6.2282699, 14.1799333, 56.6905526);
    let c5 = vec3<f32>(4.7763849, -13.7451453, -65.3530327);
    let c6 = vec3<f32>(-5.4354558, 4.6458524, 26.3124352);
    return max(c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6))))), vec3<f32>(0.0));
}

// The field at a hit: the MLS-weighted mean over the hit ball's neighbours (θ with the ball's
// h), or the ball's own value where no weight reaches.
fn field_at(hit: Hit) -> f32 {
    let nb = neighbourhood(hit.item);
    let h = balls[hit.item].h * settings.h_factor;
    let h2 = h * h;
    var sum = 0.0;
    var wsum = 0.0;
    var cursor = first_neighbours(nb);
    loop {
        let j = next_neighbour(nb, &cursor);
        if j == NO_NEIGHBOUR {
            break;
        }
        let w = weight(length_squared(points[j].position - hit.position), h2);
        sum += w * field[j];
        wsum += w;
    }
    return select(field[hit.item], sum / wsum, wsum > MIN_WEIGHT);
}

fn background(y: u32) -> vec3<f32> {
    let t = f32(y) / f32(settings.height);
    return vec3<f32>(0.03 + 0.05 * t, 0.035 + 0.05 * t, 0.05 + 0.06 * t);
}

fn status_colour(hit: Hit) -> vec3<f32> {
    // Brighter for more iterations used: where did refinement have to work?
    let work = 0.35 + 0.65 * f32(hit.iterations) / f32(max(settings.iterations, 1u));
    switch hit.status {
        case 1u: {
            return vec3<f32>(0.1, 0.7, 0.2) * work;
        }
        case 2u: {
            return vec3<f32>(0.95, 0.8, 0.1) * work;
        }
        case 5u: {
            return vec3<f32>(0.2, 0.4, 0.95);
        }
        default: {
            return vec3<f32>(0.9, 0.15, 0.1);
        }
    }
}

fn blinn_phong(n_in: vec3<f32>, dir: vec3<f32>, base: vec3<f32>) -> vec3<f32> {
    let n = select(n_in, -n_in, dot(n_in, dir) > 0.0);
    let view = -dir;
    let key = normalize(vec3<f32>(0.4, -0.3, 0.85));
    let fill = normalize(vec3<f32>(-0.6, 0.5, 0.3));
    let half_vector = normalize(key + view);
    let diffuse = 0.85 * max(dot(n, key), 0.0) + 0.25 * max(dot(n, fill), 0.0);
    let spec = 0.6 * pow(max(dot(n, half_vector), 0.0), 60.0);
    // A rim term reads the silhouette of thin sheets against the background.
    let rim = 0.25 * pow(1.0 - max(dot(n, view), 0.0), 3.0);
    return base * (0.12 + diffuse) + vec3<f32>(spec + rim);
}

@compute @workgroup_size(8, 8, 1)
fn shade(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= settings.width || gid.y >= settings.height {
        return;
    }
    let index = gid.y * settings.width + gid.x;
    let hit = hits[index];
    if hit.status == STATUS_MISS {
        image[index] = pack(background(gid.y));
        return;
    }
    let sx = (f32(gid.x) + 0.5) / f32(settings.width) * 2.0 - 1.0;
    let sy = 1.0 - (f32(gid.y) + 0.5) / f32(settings.height) * 2.0;
    let dir = normalize(settings.forward + sx * settings.right + sy * settings.up);
    var colour: vec3<f32>;
    switch settings.mode {
        case 1u: {
            colour = 0.5 + 0.5 * hit.normal;
        }
        case 2u: {
            colour = status_colour(hit);
        }
        case 3u: {
            // Back-facing hits (normal along the ray) in magenta, front faces grey.
            let back = dot(hit.normal, dir) > 0.0;
            colour = select(vec3<f32>(0.6), vec3<f32>(0.95, 0.1, 0.85), back);
            colour *= 0.4 + 0.6 * abs(dot(hit.normal, dir));
        }
        default: {
            var base = vec3<f32>(0.16, 0.42, 0.72);
            if settings.has_field != 0u && hit.item < settings.point_count {
                let span = settings.field_max - settings.field_min;
                let v = field_at(hit);
                base = viridis(select(0.5, (v - settings.field_min) / span, span > 0.0));
            }
            colour = blinn_phong(hit.normal, dir, base);
        }
    }
    image[index] = pack(colour);
}
