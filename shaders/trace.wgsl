// The trace pass: one thread per pixel. Camera ray → the baked BVH2 (stack based, nearer
// child first, pruned by the best hit) → each candidate ball's interval → its initial
// polynomial → iterative refinement (mls.wgsl) → the nearest accepted hit, an exact tie going
// to the lower item. Droplet spheres are items after the balls. Mirrors crates/mls/src/tracer.rs
// and crates/cache/src/bvh.rs. Appended to mls.wgsl.

struct Sphere {
    centre: vec3<f32>,
    radius: f32,
}

struct BvhNode {
    lo: vec3<f32>,
    count: u32,
    hi: vec3<f32>,
    first: u32,
}

@group(0) @binding(5) var<storage, read> balls: array<Ball>;
@group(0) @binding(6) var<storage, read> spheres: array<Sphere>;
@group(0) @binding(7) var<storage, read> bvh_nodes: array<BvhNode>;
@group(0) @binding(8) var<storage, read> bvh_items: array<u32>;
@group(1) @binding(0) var<storage, read_write> hits: array<Hit>;

// Deeper trees are refused at upload (slosh_render::MAX_BVH_DEPTH).
const STACK_SIZE: u32 = 64u;

// Entry parameter of the ray (t ≥ 0) into a node's box, or −1 when it misses.
fn enter(node: BvhNode, origin: vec3<f32>, inv_dir: vec3<f32>, parallel: vec3<bool>) -> f32 {
    var t0 = 0.0;
    var t1 = FAR;
    for (var a = 0u; a < 3u; a++) {
        if parallel[a] {
            if origin[a] < node.lo[a] || origin[a] > node.hi[a] {
                return -1.0;
            }
            continue;
        }
        let ta = (node.lo[a] - origin[a]) * inv_dir[a];
        let tb = (node.hi[a] - origin[a]) * inv_dir[a];
        t0 = max(t0, min(ta, tb));
        t1 = min(t1, max(ta, tb));
    }
    return select(-1.0, t0, t0 <= t1);
}

fn camera_ray(x: u32, y: u32) -> Ray {
    let sx = (f32(x) + 0.5) / f32(settings.width) * 2.0 - 1.0;
    let sy = 1.0 - (f32(y) + 0.5) / f32(settings.height) * 2.0;
    let d = settings.forward + sx * settings.right + sy * settings.up;
    return Ray(settings.eye, d / sqrt(length_squared(d)));
}

// Whether a hit at t by `item` beats the best so far (tracer.rs: nearer).
fn nearer(t: f32, item: u32, best_t: f32, best_item: u32) -> bool {
    return t < best_t || (t == best_t && item < best_item);
}

@compute @workgroup_size(8, 8, 1)
fn trace(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= settings.width || gid.y >= settings.height {
        return;
    }
    let ray = camera_ray(gid.x, gid.y);
    var best: Hit;
    best.position = vec3<f32>(0.0);
    best.t = FAR;
    best.normal = vec3<f32>(0.0);
    best.status = STATUS_MISS;
    best.item = 0xffffffffu;
    best.iterations = 0u;
    best.degree = 0u;
    best.degraded = 0u;

    let parallel = abs(ray.dir) < vec3<f32>(1e-30);
    let inv_dir = 1.0 / select(ray.dir, vec3<f32>(1.0), parallel);
    var stack_node: array<u32, STACK_SIZE>;
    var stack_t: array<f32, STACK_SIZE>;
    var sp = 0u;
    if arrayLength(&bvh_nodes) > 0u && settings.point_count + settings.sphere_count > 0u {
        let t_root = enter(bvh_nodes[0], ray.origin, inv_dir, parallel);
        if t_root >= 0.0 {
            stack_node[0] = 0u;
            stack_t[0] = t_root;
            sp = 1u;
        }
    }
    let n = settings.point_count;
    while sp > 0u {
        sp--;
        // Equal is not pruned: a tie goes to the lower item, which may lie here.
        if stack_t[sp] > best.t {
            continue;
        }
        let node = bvh_nodes[stack_node[sp]];
        if node.count > 0u {
            let end = min(node.first + node.count, arrayLength(&bvh_items));
            for (var k = node.first; k < end; k++) {
                let item = bvh_items[k];
                if item >= n {
                    if item - n >= settings.sphere_count {
                        continue;
                    }
                    let sphere = spheres[item - n];
                    let iv = ray_ball(ray, sphere.centre, sphere.radius);
                    if !iv.ok {
                        continue;
                    }
                    // From inside a droplet the ray sees its far wall.
                    let t = select(iv.t_out, iv.t_in, iv.t_in >= 0.0);
                    if !(t >= 0.0) || !nearer(t, item, best.t, best.item) {
                        continue;
                    }
                    let p = ray.origin + ray.dir * t;
                    let nrm = normalized(p - sphere.centre);
                    best.position = p;
                    best.t = t;
                    best.normal = select(vec3<f32>(0.0, 0.0, 1.0), nrm.v, nrm.ok);
                    best.status = STATUS_DROPLET;
                    best.item = item;
                    best.iterations = 0u;
                    best.degree = 0u;
                    best.degraded = 0u;
                    continue;
                }
                let ball = balls[item];
                // Unfitted balls and droplet members are never candidates.
                if (ball.state & 3u) >= 2u {
                    continue;
                }
                let point = points[item];
                let iv = ray_ball(ray, point.position, point.radius);
                if !iv.ok || iv.t_in > best.t {
                    continue;
                }
                let t_lo = max(iv.t_in, 0.0);
                if t_lo > iv.t_out {
                    continue;
                }
                var initial: Poly;
                initial.degree = min(ball.degree, 3u);
                initial.c = ball.coeffs;
                let out = intersect_ball(ray, item, ball.h, ball.normal, initial, t_lo, iv.t_out);
                if out.status != STATUS_MISS && finite(out.t) && nearer(out.t, item, best.t, best.item) {
                    best.position = ray.origin + ray.dir * out.t;
                    best.t = out.t;
                    best.normal = out.normal;
                    best.status = out.status;
                    best.item = item;
                    best.iterations = out.iterations;
                    best.degree = out.degree;
                    best.degraded = select(0u, 1u, out.degraded);
                }
            }
            continue;
        }
        let a = node.first;
        let b = node.first + 1u;
        let ta = enter(bvh_nodes[a], ray.origin, inv_dir, parallel);
        let tb = enter(bvh_nodes[b], ray.origin, inv_dir, parallel);
        // Push the farther child first so the nearer one is walked first.
        if ta >= 0.0 && tb >= 0.0 {
            if ta <= tb {
                stack_node[sp] = b;
                stack_t[sp] = tb;
                stack_node[sp + 1u] = a;
                stack_t[sp + 1u] = ta;
            } else {
                stack_node[sp] = a;
                stack_t[sp] = ta;
                stack_node[sp + 1u] = b;
                stack_t[sp + 1u] = tb;
            }
            sp += 2u;
        } else if ta >= 0.0 {
            stack_node[sp] = a;
            stack_t[sp] = ta;
            sp += 1u;
        } else if tb >= 0.0 {
            stack_node[sp] = b;
            stack_t[sp] = tb;
            sp += 1u;
        }
    }
    // No NaN reaches the buffer: a non-finite hit is reported as a miss.
    if best.status != STATUS_MISS && !(finite(best.t) && finite3(best.position) && finite3(best.normal)) {
        best.status = STATUS_MISS;
    }
    if best.status == STATUS_MISS {
        best.position = vec3<f32>(0.0);
        best.t = 0.0;
        best.normal = vec3<f32>(0.0);
        best.item = 0xffffffffu;
    }
    hits[gid.y * settings.width + gid.x] = best;
}
