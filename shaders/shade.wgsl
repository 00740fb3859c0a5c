// The shade pass: one thread per pixel, from the hit buffer to an sRGB pixel. Modes (mirrors
// `slosh_render::ShadeMode`): 0 shade (Blinn–Phong under a key, a fill and a rim light;
// coloured by a scalar field when one is bound), 1 normals, 2 status and iteration heat map,
// 3 back faces flagged. Appended to mls.wgsl and light.wgsl.

// MODE_SHADE, MODE_NORMALS, MODE_STATUS, MODE_BACKFACES: generated from `ShadeMode` by
// shaders.rs (`shared_constants_wgsl`).

// Viridis (perceptually uniform), a degree-6 fit of the matplotlib table; t in [0, 1]:
// fn colormap(which: u32, t: f32) -> vec3<f32>: generated from crates/render's colormap.rs (one source
// for the shader and legends) and prepended to this file by shaders.rs.

// Where field value v (not missing) falls on the colour map: (v - min) / (max - min) of the
// shown range, formed so that no finite v overflows (field_map.rs: FieldMap): clamped to
// within FIELD_T_LIMIT spans of the range, then scaled by the power of two that brings the
// range within [-1, 1], which changes none of its digits. An empty range maps to 0 here and
// to the map's middle in `shade`.
fn field_t(v: f32) -> f32 {
    let c = clamp(v, settings.field_clamp_low, settings.field_clamp_high);
    return (ldexp(c, settings.field_exponent) - settings.field_low) * settings.field_inverse_span;
}

// The field at a hit, as its place on the colour map: the MLS-weighted mean over the hit
// ball's neighbours (θ with the ball's h), or the ball's own value where no weight reaches;
// missing values (FIELD_MISSING, which the upload wrote over every value that is not finite)
// left out, FIELD_MISSING where there is none but those.
fn field_t_at(hit: Hit) -> f32 {
    let nb = neighbourhood(hit.item);
    let h = ball_h(hit.item) * settings.h_factor;
    let h2 = h * h;
    var sum = 0.0;
    var wsum = 0.0;
    var cursor = first_neighbours(nb);
    loop {
        let j = next_neighbour(nb, &cursor);
        if j == NO_NEIGHBOUR {
            break;
        }
        let v = field_at(j);
        if v >= FIELD_MISSING {
            continue;
        }
        let w = weight(length_squared(points_at(j).position - hit.position), h2);
        sum += w * field_t(v);
        wsum += w;
    }
    if wsum > MIN_WEIGHT {
        return sum / wsum;
    }
    let own = field_at(hit.item);
    return select(field_t(own), FIELD_MISSING, own >= FIELD_MISSING);
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

@compute @workgroup_size(8, 8, 1)
fn shade(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = frame_pixel(gid);
    if !in_frame(p) {
        return;
    }
    let index = p.y * settings.width + p.x;
    if read_status(index) == STATUS_MISS {
        image_set(index, pack(background(p.y)));
        return;
    }
    let hit = read_hit(index);
    let dir = camera_ray(p.x, p.y).dir;
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
            var base = SURFACE_COLOUR;
            if settings.has_field != 0u && hit.item < settings.point_count {
                let t = field_t_at(hit);
                base = colormap(settings.colormap, select(0.5, t, settings.field_inverse_span > 0.0));
                if t >= FIELD_MISSING {
                    base = MISSING_FIELD_COLOUR;
                }
            }
            colour = blinn_phong(hit.normal, dir, base);
        }
    }
    image_set(index, pack(colour));
}
