// The water pass (shade mode 4), the thesis's water shader (fig. 4.9) with secondary rays:
// from each primary hit, a reflected and a refracted ray (Fresnel by Schlick, index 1.33),
// the refracted one leaving the fluid where it next meets the surface; both end on a
// checkerboard floor under the fluid or the sky, and the floor is shadowed where a ray
// toward the key light meets the fluid. Secondary rays take each candidate's initial hit
// (iteration 1): they only colour, so refining them would cost without showing. Appended to
// mls.wgsl, trace.wgsl and light.wgsl.

// The stage and optics (WATER_FLOOR_BELOW, WATER_IOR, WATER_ABSORPTION, …) are generated
// from crates/render's water.rs, their one source, by shaders.rs.

// The floor and the scale of the scene, from the root's box (everything the tree holds): the
// union of entry 0's occupied slots.
struct Stage {
    floor_z: f32,
    extent: f32,
    square: f32,
}

// The floor lies a fraction of the scene's extent below its lowest point, under checker
// squares of a fraction of the extent (slosh_render::water).
fn stage() -> Stage {
    var lo = vec3<f32>(0.0);
    var hi = vec3<f32>(0.0);
    if has_nodes() {
        let w = wide_nodes_at(0u);
        let used = w.lo_x < vec4<f32>(0.5 * EMPTY_SLOT);
        let low = vec4<f32>(EMPTY_SLOT);
        let high = vec4<f32>(-EMPTY_SLOT);
        let lx = select(low, w.lo_x, used);
        let ly = select(low, w.lo_y, used);
        let lz = select(low, w.lo_z, used);
        let hx = select(high, w.hi_x, used);
        let hy = select(high, w.hi_y, used);
        let hz = select(high, w.hi_z, used);
        lo = vec3<f32>(min(min(lx.x, lx.y), min(lx.z, lx.w)), min(min(ly.x, ly.y), min(ly.z, ly.w)), min(min(lz.x, lz.y), min(lz.z, lz.w)));
        hi = vec3<f32>(max(max(hx.x, hx.y), max(hx.z, hx.w)), max(max(hy.x, hy.y), max(hy.z, hy.w)), max(max(hz.x, hz.y), max(hz.z, hz.w)));
    }
    let size = hi - lo;
    let extent = max(max(size.x, size.y), max(size.z, 1e-6));
    return Stage(lo.z - WATER_FLOOR_BELOW * extent, extent, extent / WATER_SQUARES_PER_EXTENT);
}

// Whether anything of the fluid lies along the ray (its first candidate, iteration 1).
fn blocked(origin: vec3<f32>, dir: vec3<f32>) -> bool {
    return next_candidate(Ray(origin, dir), -FAR, 0u).found;
}

// What a ray sees without the fluid: the checkerboard floor, shadowed where the key light
// is blocked, or the sky.
fn environment(origin: vec3<f32>, dir: vec3<f32>, st: Stage) -> vec3<f32> {
    if dir.z < 0.0 && origin.z > st.floor_z {
        let t = (st.floor_z - origin.z) / dir.z;
        let p = origin + dir * t;
        let cell = vec2<i32>(floor(p.xy / st.square));
        let light = select(WATER_CHECKER_LIGHT, WATER_CHECKER_DARK, ((cell.x + cell.y) & 1) == 0);
        // Grazing rays see a greyer floor, so the horizon does not alias.
        let fade = clamp(-dir.z * 4.0, 0.0, 1.0);
        var lit = WATER_FLOOR_AMBIENT + (1.0 - WATER_FLOOR_AMBIENT) * settings.key_light.z;
        if blocked(p + vec3<f32>(0.0, 0.0, 1e-4 * st.extent), settings.key_light) {
            lit = WATER_FLOOR_AMBIENT;
        }
        return mix(vec3<f32>(0.45), vec3<f32>(light), fade) * lit;
    }
    let up = clamp(dir.z, 0.0, 1.0);
    return mix(WATER_SKY_HORIZON, WATER_SKY_ZENITH, up);
}

// The surface along a ray from inside the fluid or from its surface: where it is met (t)
// and its normal there, or t < 0 for none.
struct Exit {
    t: f32,
    normal: vec3<f32>,
}

fn next_surface(origin: vec3<f32>, dir: vec3<f32>) -> Exit {
    let ray = Ray(origin, dir);
    let c = next_candidate(ray, -FAR, 0u);
    if !c.found {
        return Exit(-1.0, vec3<f32>(0.0));
    }
    return Exit(c.t, initial_outcome(ray, c).normal);
}

fn schlick(cos_i: f32) -> f32 {
    let r0 = (1.0 - WATER_IOR) / (1.0 + WATER_IOR);
    return r0 * r0 + (1.0 - r0 * r0) * pow(1.0 - cos_i, 5.0);
}

// The colour seen along `dir` from a point `p` on the fluid's surface with normal `n`
// (either orientation), arriving from outside.
fn water_colour(p: vec3<f32>, n_in: vec3<f32>, dir: vec3<f32>, st: Stage) -> vec3<f32> {
    let n = select(n_in, -n_in, dot(n_in, dir) > 0.0);
    let eps = 1e-4 * st.extent;
    let cos_i = clamp(-dot(dir, n), 0.0, 1.0);
    var fresnel = schlick(cos_i);
    // Reflection: the surface it meets (lit plainly) or the environment.
    let r = reflect(dir, n);
    let bounce = next_surface(p + r * eps, r);
    var reflected = environment(p, r, st);
    if bounce.t >= 0.0 {
        reflected = blinn_phong(bounce.normal, r, SURFACE_COLOUR);
    }
    // Refraction into the fluid, out where the ray next meets the surface.
    var refracted = vec3<f32>(0.0);
    let into = refract(dir, n, 1.0 / WATER_IOR);
    if dot(into, into) == 0.0 {
        fresnel = 1.0;
    } else {
        let exit = next_surface(p + into * eps, into);
        if exit.t < 0.0 {
            // An open sheet: the ray goes on as it entered.
            refracted = environment(p, into, st);
        } else {
            let q = p + into * (exit.t + eps);
            // The exit normal faces the ray's way out.
            let m = select(exit.normal, -exit.normal, dot(exit.normal, into) < 0.0);
            var out = refract(into, -m, WATER_IOR);
            if dot(out, out) == 0.0 {
                out = reflect(into, -m);
            }
            let tint = exp(-WATER_ABSORPTION * (exit.t / st.extent));
            refracted = environment(q, normalize(out), st) * tint;
        }
    }
    let view = -dir;
    let half_vector = normalize(settings.key_light + view);
    var spec = WATER_HIGHLIGHT * pow(max(dot(n, half_vector), 0.0), WATER_HIGHLIGHT_EXPONENT);
    if blocked(p + n * eps, settings.key_light) {
        spec = 0.0;
    }
    return fresnel * reflected + (1.0 - fresnel) * refracted + vec3<f32>(spec);
}

@compute @workgroup_size(8, 8, 1)
fn water(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = frame_pixel(gid);
    if !in_frame(p) {
        return;
    }
    let index = p.y * settings.width + p.x;
    let dir = camera_ray(p.x, p.y).dir;
    let st = stage();
    if read_status(index) == STATUS_MISS {
        image_set(index, pack(environment(settings.eye, dir, st)));
        return;
    }
    let hit = read_hit(index);
    image_set(index, pack(water_colour(hit.position, hit.normal, dir, st)));
}
