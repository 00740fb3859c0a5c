// The trace pass: one thread per pixel. Camera ray → the 4-wide tree widened from the baked
// BVH2 (widen.wgsl; stack based, nearest slot in hand, pruned by the best hit)
// → the nearest initial hit (a ball's baked polynomial inside its ball, or a droplet sphere;
// an exact tie goes to the lower item) → with more iterations, refinement of that candidate
// (mls.wgsl), handing over to the next initial hit when it leaves its ball. Droplet spheres
// are items after the balls. Mirrors crates/mls/src/tracer.rs and crates/cache/src/bvh.rs
// (the order of the walk differs; the nearest key does not). Appended to mls.wgsl;
// water.wgsl reuses its walk for secondary rays.

// Deeper trees are refused at upload (slosh_render::MAX_BVH_DEPTH).
const STACK_SIZE: u32 = 64u;

fn has_nodes() -> bool {
    return settings.node_count > 0u;
}

// The ray as the slab tests take it: t = p / d − o / d per axis, one fused multiply-add. A
// direction component below 1e-20 becomes ±1e-20: the axis then admits the box at a huge or
// never at a positive t, which can only let a box in (its items are tested exactly), never
// shut one out that the ray crosses.
struct Slab {
    inv_dir: vec3<f32>,
    scaled_origin: vec3<f32>,
}

fn slab(ray: Ray) -> Slab {
    let tiny = select(vec3<f32>(1e-20), vec3<f32>(-1e-20), ray.dir < vec3<f32>(0.0));
    let inv_dir = 1.0 / select(ray.dir, tiny, abs(ray.dir) < vec3<f32>(1e-20));
    return Slab(inv_dir, ray.origin * inv_dir);
}

// Entry parameters of the ray into a wide node's four boxes, each if it enters by `t_max`,
// else FAR (empty slots, far points, never enter).
fn enter_wide(w: Wide, s: Slab, t_max: f32) -> vec4<f32> {
    let ax = fma(w.lo_x, vec4<f32>(s.inv_dir.x), vec4<f32>(-s.scaled_origin.x));
    let bx = fma(w.hi_x, vec4<f32>(s.inv_dir.x), vec4<f32>(-s.scaled_origin.x));
    let ay = fma(w.lo_y, vec4<f32>(s.inv_dir.y), vec4<f32>(-s.scaled_origin.y));
    let by = fma(w.hi_y, vec4<f32>(s.inv_dir.y), vec4<f32>(-s.scaled_origin.y));
    let az = fma(w.lo_z, vec4<f32>(s.inv_dir.z), vec4<f32>(-s.scaled_origin.z));
    let bz = fma(w.hi_z, vec4<f32>(s.inv_dir.z), vec4<f32>(-s.scaled_origin.z));
    let near = max(max(min(ax, bx), min(ay, by)), max(min(az, bz), vec4<f32>(0.0)));
    let far = min(min(max(ax, bx), max(ay, by)), min(max(az, bz), vec4<f32>(t_max)));
    return select(vec4<f32>(FAR), near, near <= far);
}

// The frame of a ball's stored support normal (normalised from the octahedron).
fn ball_frame(b: Ball) -> Frame {
    let n = normalized(octahedral(b.normal));
    return frame_from_normal(select(vec3<f32>(0.0, 0.0, 1.0), n.v, n.ok));
}

// Two (entry, link) pairs in ascending entry.
struct Ordered {
    t_lo: f32,
    l_lo: u32,
    t_hi: f32,
    l_hi: u32,
}

fn ordered(ta: f32, la: u32, tb: f32, lb: u32) -> Ordered {
    let swap = tb < ta;
    return Ordered(select(ta, tb, swap), select(la, lb, swap), select(tb, ta, swap), select(lb, la, swap));
}

// MAX_CANDIDATES, the candidates refined per ray before it counts as a miss, is generated
// from `slosh_mls::MAX_CANDIDATES` by shaders.rs (`shared_constants_wgsl`).

// An initial hit: a ball's baked polynomial inside the ball (iteration 1), or a droplet
// sphere. Candidates are ordered by the key (t, item), an exact tie going to the lower item.
struct Candidate {
    found: bool,
    droplet: bool,
    item: u32,
    t: f32,
    // The ray's interval inside the ball, and the local hit in the ball's frame.
    t_lo: f32,
    t_out: f32,
    x: f32,
    y: f32,
}

fn key_before(t: f32, item: u32, other_t: f32, other_item: u32) -> bool {
    return t < other_t || (t == other_t && item < other_item);
}

// Tests leaf `first .. first + count`'s items against `best`: the nearest initial hit whose key
// comes after (after_t, after_item).
fn visit_leaf(ray: Ray, first: u32, count: u32, after_t: f32, after_item: u32, best: ptr<function, Candidate>) {
    let n = settings.point_count;
    let end = min(first + count, settings.item_count);
    for (var item = first; item < end; item++) {
        // An item is a ball (its point's centre and radius of trust) or a droplet sphere;
        // anything else is skipped.
        var sphere = vec4<f32>(0.0, 0.0, 0.0, -1.0);
        if item < n {
            let p = points_at(item);
            sphere = vec4<f32>(p.position, radius_of(p));
        } else if item - n < settings.sphere_count {
            let d = spheres_at(item - n);
            sphere = vec4<f32>(d.centre, d.radius);
        }
        let iv = ray_ball(ray, sphere.xyz, sphere.w);
        if !iv.ok || sphere.w < 0.0 {
            continue;
        }
        if item >= n {
            // From inside a droplet the ray sees its far wall.
            let t = select(iv.t_out, iv.t_in, iv.t_in >= 0.0);
            if t >= 0.0 && key_before(after_t, after_item, t, item)
                && key_before(t, item, (*best).t, (*best).item) {
                (*best).found = true;
                (*best).droplet = true;
                (*best).item = item;
                (*best).t = t;
            }
            continue;
        }
        let t_lo = max(iv.t_in, 0.0);
        if iv.t_in > (*best).t || iv.t_out < after_t || t_lo > iv.t_out {
            continue;
        }
        // The ball (16 bytes) is read only once the ray is known to cross its sphere.
        let ball = balls_at(item);
        if !is_candidate(ball) {
            continue;
        }
        let hit = intersect_poly(ray, sphere.xyz, ball_frame(ball), ball_poly(ball, item), ball_h(item), settings.surface_offset, t_lo, iv.t_out);
        if hit.ok && finite(hit.t) && key_before(after_t, after_item, hit.t, item)
            && key_before(hit.t, item, (*best).t, (*best).item) {
            (*best).found = true;
            (*best).droplet = false;
            (*best).item = item;
            (*best).t = hit.t;
            (*best).t_lo = t_lo;
            (*best).t_out = iv.t_out;
            (*best).x = hit.x;
            (*best).y = hit.y;
        }
    }
}

// The nearest initial hit whose key comes after (after_t, after_item), through the BVH
// (tracer.rs: next_candidate). The node in hand stays in registers: the walk descends
// through inner nodes to a leaf, nearer child first, the farther one stacked; then the leaf
// is tested, and the next node comes off the stack. Nodes entered after the best hit are
// skipped (equal is kept: a tie goes to the lower item, which may lie there).
fn next_candidate(ray: Ray, after_t: f32, after_item: u32) -> Candidate {
    var best: Candidate;
    best.found = false;
    best.t = FAR;
    best.item = 0xffffffffu;
    let ray_slab = slab(ray);
    var stack_link: array<u32, STACK_SIZE>;
    var stack_t: array<f32, STACK_SIZE>;
    var sp = 0u;
    var current = 0u;
    var live = false;
    if has_nodes() && settings.point_count + settings.sphere_count > 0u {
        // The walk starts at entry 0, the root (a lone leaf root is its one slot).
        live = true;
    }
    loop {
        // Down the 4-wide tree until the node in hand is a leaf, or nothing below it is
        // entered: the nearest entered slot is taken in hand, the others stacked.
        while live && (current >> LINK_COUNT_SHIFT) == 0u {
            let w = wide_nodes_at(current);
            let t = enter_wide(w, ray_slab, best.t);
            // The four (entry, link) pairs in ascending entry: a five-comparator network.
            let a = ordered(t.x, w.links.x, t.y, w.links.y);
            let b = ordered(t.z, w.links.z, t.w, w.links.w);
            let c = ordered(a.t_lo, a.l_lo, b.t_lo, b.l_lo);
            let d = ordered(a.t_hi, a.l_hi, b.t_hi, b.l_hi);
            let e = ordered(c.t_hi, c.l_hi, d.t_lo, d.l_lo);
            if c.t_lo >= FAR {
                live = false;
                break;
            }
            current = c.l_lo;
            // Farthest first, so the nearer come off the stack first; a slot not entered
            // is written and not kept.
            stack_link[sp] = d.l_hi;
            stack_t[sp] = d.t_hi;
            sp += select(0u, 1u, d.t_hi < FAR);
            stack_link[sp] = e.l_hi;
            stack_t[sp] = e.t_hi;
            sp += select(0u, 1u, e.t_hi < FAR);
            stack_link[sp] = e.l_lo;
            stack_t[sp] = e.t_lo;
            sp += select(0u, 1u, e.t_lo < FAR);
        }
        if live {
            visit_leaf(ray, current & LINK_FIRST, current >> LINK_COUNT_SHIFT, after_t, after_item, &best);
        }
        live = false;
        while sp > 0u {
            sp--;
            if stack_t[sp] <= best.t {
                current = stack_link[sp];
                live = true;
                break;
            }
        }
        if !live {
            break;
        }
    }
    return best;
}

// A candidate as a hit of iteration 1: the droplet's sphere point or the ball's initial
// polynomial.
fn initial_outcome(ray: Ray, c: Candidate) -> Outcome {
    var out: Outcome;
    out.t = c.t;
    out.iterations = 0u;
    out.degree = 0u;
    out.degraded = false;
    let p = ray.origin + ray.dir * c.t;
    if c.droplet {
        let nrm = normalized(p - spheres_at(c.item - settings.point_count).centre);
        out.status = STATUS_DROPLET;
        out.normal = select(vec3<f32>(0.0, 0.0, 1.0), nrm.v, nrm.ok);
        return out;
    }
    let ball = balls_at(c.item);
    let initial = ball_poly(ball, c.item);
    out.status = STATUS_ITERATION_LIMIT;
    out.normal = hit_normal(ball_frame(ball), initial, c.x, c.y);
    out.iterations = 1u;
    out.degree = initial.degree;
    out.degraded = initial.degree < settings.degree;
    return out;
}

// Writes pixel `p`'s hit; no NaN reaches the buffer: a non-finite hit is a miss.
fn store(p: vec2<u32>, ray: Ray, item: u32, out: Outcome) {
    var hit: Hit;
    hit.position = ray.origin + ray.dir * out.t;
    hit.t = out.t;
    hit.normal = out.normal;
    hit.status = out.status;
    hit.item = item;
    hit.iterations = out.iterations;
    hit.degree = out.degree;
    hit.degraded = select(0u, 1u, out.degraded);
    if hit.status != STATUS_MISS && !(finite(hit.t) && finite3(hit.position) && finite3(hit.normal)) {
        hit.status = STATUS_MISS;
    }
    let pixel = p.y * settings.width + p.x;
    if hit.status == STATUS_MISS {
        write_miss(pixel);
        return;
    }
    write_hit(pixel, hit);
}

fn missed() -> Outcome {
    var out: Outcome;
    out.status = STATUS_MISS;
    return out;
}

// One iteration: the nearest initial hit, with no refinement code to weigh the kernel down.
@compute @workgroup_size(8, 8, 1)
fn trace_initial(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = frame_pixel(gid);
    if !in_frame(p) {
        return;
    }
    let ray = camera_ray(p.x, p.y);
    let c = next_candidate(ray, -FAR, 0u);
    if !c.found {
        store(p, ray, 0u, missed());
        return;
    }
    store(p, ray, c.item, initial_outcome(ray, c));
}

// More iterations: candidates in the order of their initial hits; the first whose refinement
// stays inside its ball is the hit (Adamson & Alexa 2003; tracer.rs: trace_in).
@compute @workgroup_size(8, 8, 1)
fn trace_refined(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = frame_pixel(gid);
    if !in_frame(p) {
        return;
    }
    let ray = camera_ray(p.x, p.y);
    var after_t = -FAR;
    var after_item = 0u;
    for (var attempt = 0u; attempt < MAX_CANDIDATES; attempt++) {
        let c = next_candidate(ray, after_t, after_item);
        if !c.found {
            break;
        }
        let start = initial_outcome(ray, c);
        if c.droplet {
            store(p, ray, c.item, start);
            return;
        }
        let out = refine(ray, c.item, ball_h(c.item), start, c.t_lo, c.t_out);
        if out.status != STATUS_MISS && finite(out.t) {
            store(p, ray, c.item, out);
            return;
        }
        after_t = c.t;
        after_item = c.item;
    }
    store(p, ray, 0u, missed());
}
