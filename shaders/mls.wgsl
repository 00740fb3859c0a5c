// The MLS surface maths of `crates/mls`, ported line for line (docs/algorithm.md is the
// specification): a step's balls and neighbour lists (visited through expand.wgsl's masks),
// polynomials along lines, exact roots and the iteration; fit.wgsl holds the fit itself.
// Shared by trace.wgsl and shade.wgsl, which are appended to these two.

// A ball's initial support normal and polynomial. Mirrors `slosh_cache::GpuBall`: the
// support normal (octahedral) and the first six coefficients as half floats two to a word (a
// droplet member's first word names its sphere instead); a cubic's other four are in
// `ball_cubic` (two words per ball).
struct Ball {
    normal: u32,
    coeffs: array<u32, 3>,
}

// Ball i's state (slosh_cache::BallBits): four bits, eight balls to a word of ball_states;
// bits 0–1 what it is (0 full, 1 degraded, 2 unfitted, 3 droplet member), 2–3 the degree.
fn ball_state(i: u32) -> u32 {
    return (ball_states_at(i >> 3u) >> ((i & 7u) * 4u)) & 15u;
}

// Unfitted balls and droplet members (states 2 and 3) are never candidates, and they alone
// have no normal (the octahedral "no normal", first coordinate −32768), so the ball tells.
fn is_candidate(b: Ball) -> bool {
    return (b.normal & 0xffffu) != 0x8000u;
}

// How a pass learns a ball's degree and h: pipeline constants the trace and water passes
// are built with for the step drawn (crates/render's tracer, BallKnowledge), so that the
// common step compiles neither fallback into the walk: BALL_DEGREE 0–3 every ball's degree,
// 4 each ball's state; BALL_H 0 the step's h, 1 each ball's. Any other value (the defaults,
// for passes that do not set them) decides from the settings at run time.
override BALL_DEGREE: u32 = 5u;
override BALL_H: u32 = 2u;

// Ball i's own degree, from its state.
fn state_degree(i: u32) -> u32 {
    return ball_state(i) >> 2u;
}

// The degree ball i was fitted at: the step's one degree where it has no degraded fits
// (settings.ball_degree ≤ 3), so the walk reads no state, else the ball's state.
fn ball_degree(i: u32) -> u32 {
    if BALL_DEGREE <= 3u {
        return BALL_DEGREE;
    }
    if BALL_DEGREE == 4u {
        return state_degree(i);
    }
    if settings.ball_degree <= 3u {
        return settings.ball_degree;
    }
    return state_degree(i);
}

// Ball i's own h, from ball_h (two half floats to a word). Normal half floats (the verifier
// refuses any other), so every adapter decodes what the CPU does.
fn own_h(i: u32) -> f32 {
    let pair = unpack2x16float(ball_h_at(i >> 1u));
    return select(pair.x, pair.y, (i & 1u) == 1u);
}

// Ball i's smoothing length: the step's one h, or its own where h is per point.
fn ball_h(i: u32) -> f32 {
    if BALL_H == 0u {
        return settings.h;
    }
    if BALL_H == 1u {
        return own_h(i);
    }
    if settings.per_point_h != 0u {
        return own_h(i);
    }
    return settings.h;
}

// One pixel of the hit buffer; mirrors `slosh_render::GpuHit`. Position and t are in the
// cache's local coordinates.
struct Hit {
    position: vec3<f32>,
    t: f32,
    normal: vec3<f32>,
    status: u32,
    item: u32,
    iterations: u32,
    degree: u32,
    degraded: u32,
}

// Camera (already in the cache's local coordinates) and tracing parameters; mirrors
// `slosh_render::GpuSettings`.
struct Settings {
    eye: vec3<f32>,
    width: u32,
    // Camera basis scaled by the image plane's half extent: ray = forward + sx right + sy up.
    right: vec3<f32>,
    height: u32,
    up: vec3<f32>,
    iterations: u32,
    forward: vec3<f32>,
    degree: u32,
    epsilon: f32,
    // Multiplies each ball's baked smoothing length during refinement (1 = as baked).
    h_factor: f32,
    // 0 mean normals (falling back to the covariance), 1 covariance.
    normals_mode: u32,
    has_normals: u32,
    point_count: u32,
    sphere_count: u32,
    cluster_size: u32,
    mode: u32,
    // The shown field range's minimum and 1 / span, scaled by 2^field_exponent
    // (field_map.rs: FieldMap).
    field_low: f32,
    field_inverse_span: f32,
    has_field: u32,
    // Words of neighbour mask of the largest cluster.
    mask_words: u32,
    // Nodes of the BVH2 (entries of the 4-wide tree widened from it), and the items its
    // leaves range over (balls, then droplet spheres).
    node_count: u32,
    item_count: u32,
    // The field's colour map (colormap.rs: Colormap).
    colormap: u32,
    // The rows this dispatch covers: every row_stride-th from first_row (layout.rs:
    // GpuSettings::first_row).
    first_row: u32,
    // Unit direction towards the key light (the shade and water passes).
    key_light: vec3<f32>,
    row_stride: u32,
    // How far outside the MLS surface the drawn surface lies along its normal, in local
    // units (docs/algorithm.md: the offset).
    surface_offset: f32,
    // The step's h (a half float), and whether each ball has its own instead (ball_h).
    h: f32,
    per_point_h: u32,
    // The degree every ball was fitted at, or 4 where some are degraded (layout.rs).
    ball_degree: u32,
    // The rest of the field map: the power of two that brings the shown range within
    // [-1, 1], and the values beyond which a field value counts as lying there.
    field_exponent: i32,
    field_clamp_low: f32,
    field_clamp_high: f32,
}

// The step's arrays are read through accessors (`points_at(i)`, …) that crates/render's
// shaders.rs generates over the ranges they are bound in. Among them: neighbour_masks, bit
// masks over each point's cluster candidates (group 2), written by expand.wgsl before a step's
// first refined frame.
// The uniforms belong to the frame (group 1), so a step's bind group (group 0) is made once
// per step and serves any frame.
@group(1) @binding(100) var<uniform> settings: Settings;
// The frame's hits (`hits_at`), three 16-byte words per pixel in `Hit`'s layout: whole-word
// stores keep the trace pass's writes coalesced (a struct store became twelve 4-byte ones,
// which cost as much as a fifth of a 1-iteration frame).

fn write_hit(pixel: u32, hit: Hit) {
    let at = 3u * pixel;
    hits_set(at, vec4<u32>(bitcast<vec3<u32>>(hit.position), bitcast<u32>(hit.t)));
    hits_set(at + 1u, vec4<u32>(bitcast<vec3<u32>>(hit.normal), hit.status));
    hits_set(at + 2u, vec4<u32>(hit.item, hit.iterations, hit.degree, hit.degraded));
}

// A miss writes its status word alone (a third of the bytes; most pixels miss): the other
// words keep whatever they held, and the host zeroes them on readback (Tracer::render).
fn write_miss(pixel: u32) {
    hits_set(3u * pixel + 1u, vec4<u32>(0u, 0u, 0u, STATUS_MISS));
}

fn read_status(pixel: u32) -> u32 {
    return hits_at(3u * pixel + 1u).w;
}

fn read_hit(pixel: u32) -> Hit {
    let at = 3u * pixel;
    let a = hits_at(at);
    let b = hits_at(at + 1u);
    let c = hits_at(at + 2u);
    return Hit(bitcast<vec3<f32>>(a.xyz), bitcast<f32>(a.w), bitcast<vec3<f32>>(b.xyz), b.w, c.x, c.y, c.z, c.w);
}

// ---- Neighbour lists (clusters.rs: expand_one) ----------------------------------------------

// A ball's neighbours are its cluster's candidates within reach, minus points whose normal
// opposes the centre's (both valid). expand.wgsl applies that rule once per step and leaves a
// bit per candidate slot: bit b of word w for slot 32 w + b, member m's words at
// `mask_row * cluster_size + m * words` (step.wgsl). Visiting set bits in order visits the
// list in index order, as the CPU does.
struct Neighbourhood {
    // The cluster's first candidate slot in `candidates` (step.wgsl).
    first: u32,
    // Index of the member's word 0.
    mask: u32,
    words: u32,
}

fn neighbourhood(centre: u32) -> Neighbourhood {
    let size = max(settings.cluster_size, 1u);
    let c = centre / size;
    let first = cluster_start_at(c);
    let last = cluster_start_at(c + 1u);
    let count = select(0u, last - first, last > first);
    // The largest cluster's words bound any other's.
    let words = min((count + 31u) / 32u, settings.mask_words);
    return Neighbourhood(first, mask_row(c, first) * size + (centre % size) * words, words);
}

// Where a walk over a neighbourhood stands: the current word and its unvisited bits.
struct Cursor {
    word: u32,
    bits: u32,
}

fn first_neighbours(nb: Neighbourhood) -> Cursor {
    return Cursor(0u, select(0u, neighbour_masks_at(nb.mask), nb.words > 0u));
}

// The next neighbour's point index, or NO_NEIGHBOUR after the last.
fn next_neighbour(nb: Neighbourhood, cursor: ptr<function, Cursor>) -> u32 {
    while (*cursor).bits == 0u {
        (*cursor).word += 1u;
        if (*cursor).word >= nb.words {
            return NO_NEIGHBOUR;
        }
        (*cursor).bits = neighbour_masks_at(nb.mask + (*cursor).word);
    }
    let bits = (*cursor).bits;
    (*cursor).bits = bits & (bits - 1u);
    return candidates_at(nb.first + (*cursor).word * 32u + firstTrailingBit(bits));
}

// ---- Polynomials (poly.rs) ------------------------------------------------------------------

// Ball `item`'s stored initial polynomial as f32, exactly the stored values
// (slosh_cache::GpuBall::coeffs): half floats, the first six in the ball, a cubic's other
// four in `ball_cubic`.
fn ball_poly(b: Ball, item: u32) -> Poly {
    var p: Poly;
    p.degree = ball_degree(item);
    let w = b.coeffs;
    var e = vec2<u32>(0u);
    if p.degree == 3u {
        e = ball_cubic_at(item);
    }
    // Half floats as f32, exactly: the bake stores no subnormal (slosh_cache::GpuBall), so
    // an adapter that flushes them decodes the same values. On the H200 this ran 1 % faster
    // than format 4's decoding at 1 iteration; bit arithmetic that keeps subnormals ran 9 %
    // slower, and subnormals assembled apart 3.5 % slower.
    let c01 = unpack2x16float(w[0]);
    let c23 = unpack2x16float(w[1]);
    let c45 = unpack2x16float(w[2]);
    let c67 = unpack2x16float(e.x);
    let c89 = unpack2x16float(e.y);
    p.c = array<f32, 10>(c01.x, c01.y, c23.x, c23.y, c45.x, c45.y, c67.x, c67.y, c89.x, c89.y);
    return p;
}

fn poly_gradient(p: Poly, x: f32, y: f32) -> vec2<f32> {
    let c = p.c;
    let fx = c[1] + 2.0 * c[3] * x + c[5] * y + 3.0 * c[6] * x * x + 2.0 * c[8] * x * y + c[9] * y * y;
    let fy = c[2] + 2.0 * c[4] * y + c[5] * x + 3.0 * c[7] * y * y + c[8] * x * x + 2.0 * c[9] * x * y;
    return vec2<f32>(fx, fy);
}

// Products of polynomials in s whose zero coefficients are known, so only the others are
// multiplied: linear × linear (Poly::along_line's mul, with its zero terms dropped: adding
// an exact zero changes no sum, so the result is the same).
fn lin_mul(a: vec2<f32>, b: vec2<f32>) -> vec3<f32> {
    return vec3<f32>(a[0] * b[0], a[0] * b[1] + a[1] * b[0], a[1] * b[1]);
}

// Quadratic × linear.
fn quad_mul(q: vec3<f32>, l: vec2<f32>) -> vec4<f32> {
    return vec4<f32>(q[0] * l[0], q[0] * l[1] + q[1] * l[0], q[1] * l[1] + q[2] * l[0], q[2] * l[1]);
}

// Coefficients (ascending powers of s) of s ↦ f(x0 + s dx, y0 + s dy) (Poly::along_line),
// each power summed over the terms in the same order, with constant indices only: a
// dynamically indexed array would live in slow per-thread memory on a GPU.
fn along_line(p: Poly, x0: f32, y0: f32, dx: f32, dy: f32) -> vec4<f32> {
    let c = p.c;
    let x = vec2<f32>(x0, dx);
    let y = vec2<f32>(y0, dy);
    // Powers s⁰ and s¹, then s² and s³.
    var low = vec2<f32>(c[0], 0.0);
    var s2 = 0.0;
    var s3 = 0.0;
    if p.degree >= 1u {
        low += c[1] * x;
        low += c[2] * y;
    }
    if p.degree >= 2u {
        let xx = lin_mul(x, x);
        let yy = lin_mul(y, y);
        let xy = lin_mul(x, y);
        low += c[3] * xx.xy;
        s2 += c[3] * xx.z;
        low += c[4] * yy.xy;
        s2 += c[4] * yy.z;
        low += c[5] * xy.xy;
        s2 += c[5] * xy.z;
        if p.degree >= 3u {
            let xxx = quad_mul(xx, x);
            let yyy = quad_mul(yy, y);
            let xxy = quad_mul(xx, y);
            let xyy = quad_mul(yy, x);
            low += c[6] * xxx.xy;
            s2 += c[6] * xxx.z;
            s3 += c[6] * xxx.w;
            low += c[7] * yyy.xy;
            s2 += c[7] * yyy.z;
            s3 += c[7] * yyy.w;
            low += c[8] * xxy.xy;
            s2 += c[8] * xxy.z;
            s3 += c[8] * xxy.w;
            low += c[9] * xyy.xy;
            s2 += c[9] * xyy.z;
            s3 += c[9] * xyy.w;
        }
    }
    return vec4<f32>(low, s2, s3);
}

// ---- Roots (roots.rs) -----------------------------------------------------------------------

fn eval_cubic(c: vec4<f32>, s: f32) -> f32 {
    return ((c[3] * s + c[2]) * s + c[1]) * s + c[0];
}

fn derivative_cubic(c: vec4<f32>, s: f32) -> f32 {
    return (3.0 * c[3] * s + 2.0 * c[2]) * s + c[1];
}

struct Roots {
    count: u32,
    r: vec2<f32>,
}

// Real roots of a s² + b s + c, ascending, without cancellation.
fn quadratic_roots(a: f32, b: f32, c: f32) -> Roots {
    if a == 0.0 {
        if b == 0.0 {
            return Roots(0u, vec2<f32>(0.0));
        }
        return Roots(1u, vec2<f32>(-c / b, 0.0));
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return Roots(0u, vec2<f32>(0.0));
    }
    let q = -(b + signum(b) * sqrt(disc)) * 0.5;
    if q == 0.0 {
        return Roots(2u, vec2<f32>(0.0));
    }
    let r1 = q / a;
    let r2 = c / q;
    return Roots(2u, vec2<f32>(min(r1, r2), max(r1, r2)));
}

// Root of h in [a, b], h(a) with the sign of fa and h(b) the other: Newton inside the bracket.
fn bracketed_root(c: vec4<f32>, a_in: f32, b_in: f32, fa: f32) -> f32 {
    var a = a_in;
    var b = b_in;
    let sa = signum(fa);
    var s = (a + b) * 0.5;
    for (var i = 0u; i < 100u; i++) {
        let f = eval_cubic(c, s);
        if f == 0.0 {
            return s;
        }
        if signum(f) == sa {
            a = s;
        } else {
            b = s;
        }
        let df = derivative_cubic(c, s);
        let newton = s - f / df;
        var next = (a + b) * 0.5;
        if newton > a && newton < b && finite(newton) {
            next = newton;
        }
        if next == s || b - a <= F32_EPSILON * (abs(a) + abs(b)) {
            return next;
        }
        s = next;
    }
    return s;
}

struct Root {
    ok: bool,
    s: f32,
}

// The smallest root of c0 + c1 s + c2 s² + c3 s³ in [lo, hi] (first_root_in).
fn first_root_in(c: vec4<f32>, lo: f32, hi: f32) -> Root {
    let none = Root(false, 0.0);
    if !(lo <= hi) || !finite(c[0]) || !finite(c[1]) || !finite(c[2]) || !finite(c[3]) {
        return none;
    }
    if c[3] == 0.0 {
        let q = quadratic_roots(c[2], c[1], c[0]);
        for (var i = 0u; i < q.count; i++) {
            if q.r[i] >= lo && q.r[i] <= hi {
                return Root(true, q.r[i]);
            }
        }
        return none;
    }
    let crit = quadratic_roots(3.0 * c[3], 2.0 * c[2], c[1]);
    // Piece boundaries; a vector, not an array, so it stays in registers.
    var pts = vec4<f32>(lo, hi, hi, hi);
    var k = 1u;
    for (var i = 0u; i < crit.count; i++) {
        let s = crit.r[i];
        if s > lo && s < hi {
            pts[k] = s;
            k++;
        }
    }
    pts[k] = hi;
    let scale = abs(c[0]) + abs(c[1]) + abs(c[2]) + abs(c[3]);
    let touch = 64.0 * F32_EPSILON * max(scale, F32_MIN_POSITIVE);
    for (var i = 0u; i < k; i++) {
        let a = pts[i];
        let b = pts[i + 1u];
        let fa = eval_cubic(c, a);
        let fb = eval_cubic(c, b);
        if fa == 0.0 {
            return Root(true, a);
        }
        if signum(fa) != signum(fb) {
            return Root(true, bracketed_root(c, a, b, fa));
        }
        if i + 1u < k && abs(fb) <= touch {
            return Root(true, b);
        }
    }
    if eval_cubic(c, hi) == 0.0 {
        return Root(true, hi);
    }
    return none;
}

// ---- Ray against a polynomial and a ball (intersect.rs) -------------------------------------

struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
}

// The camera ray through the centre of pixel (x, y), y down (Camera::ray); shared by the
// passes.
// The pixel an invocation of a frame pass covers: a dispatch covers every row_stride-th row
// from first_row (the whole frame when 0 and 1).
fn frame_pixel(gid: vec3<u32>) -> vec2<u32> {
    return vec2<u32>(gid.x, settings.first_row + gid.y * settings.row_stride);
}

fn in_frame(p: vec2<u32>) -> bool {
    return p.x < settings.width && p.y < settings.height;
}

fn camera_ray(x: u32, y: u32) -> Ray {
    let sx = (f32(x) + 0.5) / f32(settings.width) * 2.0 - 1.0;
    let sy = 1.0 - (f32(y) + 0.5) / f32(settings.height) * 2.0;
    let d = settings.forward + sx * settings.right + sy * settings.up;
    return Ray(settings.eye, d / sqrt(length_squared(d)));
}

struct Interval {
    ok: bool,
    t_in: f32,
    t_out: f32,
}

fn ray_ball(ray: Ray, centre: vec3<f32>, radius: f32) -> Interval {
    let oc = centre - ray.origin;
    let tc = dot(oc, ray.dir);
    let perp = oc - ray.dir * tc;
    let d2 = length_squared(perp);
    let r2 = radius * radius;
    if !(d2 <= r2) {
        return Interval(false, 0.0, 0.0);
    }
    let half = sqrt(r2 - d2);
    return Interval(true, tc - half, tc + half);
}

struct PolyHit {
    ok: bool,
    t: f32,
    x: f32,
    y: f32,
}

// Where the ray meets `p` (set at `r` in `frame`) raised by `offset` along the frame's normal,
// first in [t_lo, t_hi] (intersect.rs: intersect_poly).
fn intersect_poly(ray: Ray, r: vec3<f32>, frame: Frame, p: Poly, h: f32, offset: f32, t_lo: f32, t_hi: f32) -> PolyHit {
    let rel = ray.origin - r;
    let t0 = min(max(-dot(rel, ray.dir), t_lo), t_hi);
    let inv_h = 1.0 / h;
    let q0 = to_local(frame, rel + ray.dir * t0) * inv_h;
    let dl = to_local(frame, ray.dir);
    var c = along_line(p, q0.x, q0.y, dl.x, dl.y);
    c[0] = c[0] + offset * inv_h - q0.z;
    c[1] = c[1] - dl.z;
    let root = first_root_in(c, (t_lo - t0) * inv_h, (t_hi - t0) * inv_h);
    if !root.ok {
        return PolyHit(false, 0.0, 0.0, 0.0);
    }
    return PolyHit(true, t0 + root.s * h, q0.x + root.s * dl.x, q0.y + root.s * dl.y);
}

fn hit_normal(frame: Frame, p: Poly, x: f32, y: f32) -> vec3<f32> {
    let g = poly_gradient(p, x, y);
    let n = normalized(frame.n - frame.u * g.x - frame.v * g.y);
    return select(frame.n, n.v, n.ok);
}

// Hit statuses, numbered as the hit buffer's status channel: STATUS_MISS, _CONVERGED,
// _ITERATION_LIMIT, _NO_SUPPORT, _DEGENERATE_FIT, _DROPLET, generated from
// `slosh_render::status` by shaders.rs (`shared_constants_wgsl`).

struct Outcome {
    status: u32,
    t: f32,
    normal: vec3<f32>,
    iterations: u32,
    degree: u32,
    degraded: bool,
}

// Iterations 2 and on from a ball's initial hit `start` (iteration 1, status iteration limit),
// with the centre's neighbours (refine). Leaving the ball comes back with STATUS_MISS.
fn refine(ray: Ray, centre: u32, bh: f32, start: Outcome, t_lo: f32, t_out: f32) -> Outcome {
    var out = start;
    let h = bh * settings.h_factor;
    let nb = neighbourhood(centre);
    let limit = max(settings.iterations, 1u);
    while out.iterations < limit {
        let r = ray.origin + ray.dir * out.t;
        let support = support_normal(r, nb, h, ray.origin);
        if !support.ok {
            out.status = STATUS_NO_SUPPORT;
            break;
        }
        let frame = frame_from_normal(support.normal);
        let f = fit(r, frame, nb, h);
        if !f.ok {
            out.status = STATUS_DEGENERATE_FIT;
            break;
        }
        out.degraded = out.degraded || f.degraded;
        let next = intersect_poly(ray, r, frame, f.poly, h, settings.surface_offset, t_lo, t_out);
        if !next.ok {
            // Left the trust region: no hit from this ball.
            out.status = STATUS_MISS;
            out.iterations += 1u;
            return out;
        }
        out.iterations += 1u;
        let dt = abs(next.t - out.t);
        out.t = next.t;
        out.normal = hit_normal(frame, f.poly, next.x, next.y);
        out.degree = f.poly.degree;
        if dt < settings.epsilon * h {
            out.status = STATUS_CONVERGED;
            break;
        }
    }
    return out;
}
