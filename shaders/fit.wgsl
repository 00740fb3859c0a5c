// The MLS fit of `crates/mls`, ported line for line (docs/algorithm.md): weights, the local
// frame, the support plane and the scaled polynomial fit with degree degradation. Shared by
// the tracer's passes (appended to mls.wgsl) and the bake's initial fits (bake_fit.wgsl).
// Over an abstract neighbourhood: the module it is part of defines `Neighbourhood`,
// `first_neighbours`, `next_neighbour` (NO_NEIGHBOUR after the last), `points_at(j).position`,
// `normal_at(j)`, and `settings.has_normals` and `settings.normals_mode`.

const F32_EPSILON: f32 = 1.1920929e-7;
const F32_MIN_POSITIVE: f32 = 1.17549435e-38;
// 2^64, a stand-in for +∞ in comparisons (WGSL may assume no infinities).
const FAR: f32 = 1.8446744e19;
// support.rs: MIN_WEIGHT and CANCELLATION; fit.rs: PIVOT_TOLERANCE.
const MIN_WEIGHT: f32 = 1e-6;
const CANCELLATION: f32 = 0.5;
const PIVOT_TOLERANCE: f32 = 1e-5;

// Bit tests, because WGSL lets a compiler assume floats are never NaN or infinite.
fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn finite3(v: vec3<f32>) -> bool {
    return finite(v.x) && finite(v.y) && finite(v.z);
}

// Rust's f32::signum: ±1 by the sign bit (so +0 → 1, −0 → −1), unlike WGSL's sign().
fn signum(x: f32) -> f32 {
    return select(1.0, -1.0, (bitcast<u32>(x) >> 31u) == 1u);
}

// θ(d) = exp(−d²/h²).
fn weight(d2: f32, h2: f32) -> f32 {
    return exp(-d2 / h2);
}

fn length_squared(v: vec3<f32>) -> f32 {
    return v.x * v.x + v.y * v.y + v.z * v.z;
}

// V3::normalized: the unit vector, or (false) when the length is not a usable positive number.
struct Unit {
    ok: bool,
    v: vec3<f32>,
}

fn normalized(v: vec3<f32>) -> Unit {
    let len = sqrt(length_squared(v));
    if finite(len) && len > sqrt(F32_MIN_POSITIVE) {
        return Unit(true, v * (1.0 / len));
    }
    return Unit(false, vec3<f32>(0.0));
}

// ---- Local frame (frame.rs) -----------------------------------------------------------------

struct Frame {
    u: vec3<f32>,
    v: vec3<f32>,
    n: vec3<f32>,
}

fn frame_from_normal(n: vec3<f32>) -> Frame {
    let s = signum(n.z);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    let u = vec3<f32>(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    let v = vec3<f32>(b, s + n.y * n.y * a, -n.y);
    return Frame(u, v, n);
}

fn to_local(f: Frame, w: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(f.u, w), dot(f.v, w), dot(f.n, w));
}

// ---- Support plane (support.rs) -------------------------------------------------------------

struct Support {
    ok: bool,
    normal: vec3<f32>,
}

struct Eigen {
    values: vec3<f32>,
    // Columns are eigenvectors.
    vectors: mat3x3<f32>,
}

// Cyclic Jacobi rotations over (0,1), (0,2), (1,2), at most 16 sweeps (jacobi_eigen).
fn jacobi_eigen(m: mat3x3<f32>) -> Eigen {
    // a[row][col], stored as a flat array to allow dynamic indices.
    var a: array<f32, 9>;
    var v: array<f32, 9>;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            a[i * 3u + j] = m[j][i];
            v[i * 3u + j] = select(0.0, 1.0, i == j);
        }
    }
    for (var sweep = 0u; sweep < 16u; sweep++) {
        let off = a[1] * a[1] + a[2] * a[2] + a[5] * a[5];
        let diag = a[0] * a[0] + a[4] * a[4] + a[8] * a[8];
        if !(off > F32_EPSILON * F32_EPSILON * diag) {
            break;
        }
        for (var pair = 0u; pair < 3u; pair++) {
            let p = select(0u, 1u, pair == 2u);
            let q = select(1u, 2u, pair != 0u);
            let apq = a[p * 3u + q];
            if apq == 0.0 {
                continue;
            }
            let theta = (a[q * 3u + q] - a[p * 3u + p]) / (2.0 * apq);
            var t = signum(theta) / (abs(theta) + sqrt(theta * theta + 1.0));
            if !finite(theta) || !finite(t) {
                t = 0.0;
            }
            let c = 1.0 / sqrt(t * t + 1.0);
            let s = t * c;
            for (var k = 0u; k < 3u; k++) {
                let akp = a[k * 3u + p];
                let akq = a[k * 3u + q];
                a[k * 3u + p] = c * akp - s * akq;
                a[k * 3u + q] = s * akp + c * akq;
            }
            for (var k = 0u; k < 3u; k++) {
                let apk = a[p * 3u + k];
                let aqk = a[q * 3u + k];
                a[p * 3u + k] = c * apk - s * aqk;
                a[q * 3u + k] = s * apk + c * aqk;
            }
            for (var k = 0u; k < 3u; k++) {
                let vkp = v[k * 3u + p];
                let vkq = v[k * 3u + q];
                v[k * 3u + p] = c * vkp - s * vkq;
                v[k * 3u + q] = s * vkp + c * vkq;
            }
        }
    }
    var out: Eigen;
    out.values = vec3<f32>(a[0], a[4], a[8]);
    out.vectors = mat3x3<f32>(
        vec3<f32>(v[0], v[3], v[6]),
        vec3<f32>(v[1], v[4], v[7]),
        vec3<f32>(v[2], v[5], v[8]),
    );
    return out;
}

// Smallest-eigenvalue eigenvector of B = Σθ (p−r)(p−r)ᵀ / (h² Σθ) (covariance_normal).
fn covariance_normal(r: vec3<f32>, nb: Neighbourhood, h2: f32, weight_sum: f32) -> vec3<f32> {
    var b00 = 0.0;
    var b01 = 0.0;
    var b02 = 0.0;
    var b11 = 0.0;
    var b12 = 0.0;
    var b22 = 0.0;
    let scale = 1.0 / (h2 * weight_sum);
    var cursor = first_neighbours(nb);
    loop {
        let j = next_neighbour(nb, &cursor);
        if j == NO_NEIGHBOUR {
            break;
        }
        let q = points_at(j).position - r;
        let w = weight(length_squared(q), h2) * scale;
        b00 += w * q.x * q.x;
        b01 += w * q.x * q.y;
        b02 += w * q.x * q.z;
        b11 += w * q.y * q.y;
        b12 += w * q.y * q.z;
        b22 += w * q.z * q.z;
    }
    let e = jacobi_eigen(mat3x3<f32>(
        vec3<f32>(b00, b01, b02),
        vec3<f32>(b01, b11, b12),
        vec3<f32>(b02, b12, b22),
    ));
    // The first index of the smallest eigenvalue (a stable sort's first element).
    var k = 0u;
    if e.values[1] < e.values[k] {
        k = 1u;
    }
    if e.values[2] < e.values[k] {
        k = 2u;
    }
    let n = normalized(e.vectors[k]);
    return select(vec3<f32>(0.0, 0.0, 1.0), n.v, n.ok);
}

// The support plane normal at r from the neighbourhood, smoothing length h (support_normal).
fn support_normal(r: vec3<f32>, nb: Neighbourhood, h: f32, toward: vec3<f32>) -> Support {
    let h2 = h * h;
    var weight_sum = 0.0;
    var mean = vec3<f32>(0.0);
    var magnitude = 0.0;
    let use_normals = settings.has_normals != 0u;
    var cursor = first_neighbours(nb);
    loop {
        let j = next_neighbour(nb, &cursor);
        if j == NO_NEIGHBOUR {
            break;
        }
        let w = weight(length_squared(points_at(j).position - r), h2);
        weight_sum += w;
        if use_normals {
            let n = normalized(normal_at(j));
            if n.ok {
                mean += n.v * w;
                magnitude += w;
            }
        }
    }
    if !(weight_sum > MIN_WEIGHT) {
        return Support(false, vec3<f32>(0.0));
    }
    if settings.normals_mode == 0u {
        let len = sqrt(length_squared(mean));
        if magnitude > 0.0 && len >= CANCELLATION * magnitude {
            return Support(true, mean * (1.0 / len));
        }
    }
    let normal = covariance_normal(r, nb, h2, weight_sum);
    // Orientation: the weighted majority of the data normals, else toward the ray origin.
    var vote = 0.0;
    if use_normals {
        var cursor = first_neighbours(nb);
        loop {
            let j = next_neighbour(nb, &cursor);
            if j == NO_NEIGHBOUR {
                break;
            }
            let n = normalized(normal_at(j));
            if n.ok {
                let w = weight(length_squared(points_at(j).position - r), h2);
                vote += w * signum(dot(n.v, normal));
            }
        }
    }
    var flip = dot(toward - r, normal) < 0.0;
    if vote != 0.0 {
        flip = vote < 0.0;
    }
    return Support(true, select(normal, -normal, flip));
}

// ---- Polynomials (poly.rs) ------------------------------------------------------------------

fn coefficient_count(degree: u32) -> u32 {
    switch degree {
        case 0u: {
            return 1u;
        }
        case 1u: {
            return 3u;
        }
        case 2u: {
            return 6u;
        }
        default: {
            return 10u;
        }
    }
}

struct Poly {
    degree: u32,
    c: array<f32, 10>,
}

// ---- Weighted least squares fit (fit.rs) ----------------------------------------------------

struct Fit {
    ok: bool,
    degraded: bool,
    poly: Poly,
}

// Index of (i, j), j ≤ i, in a packed lower triangle.
fn tri(i: u32, j: u32) -> u32 {
    return i * (i + 1u) / 2u + j;
}

// The refinement fits' requested degree (Params::degree), fixed per pipeline: the fit's loops
// then have constant bounds, which lets a compiler unroll them and keep A in registers.
override FIT_DEGREE: u32 = 2u;

fn fit(r: vec3<f32>, frame: Frame, nb: Neighbourhood, h: f32) -> Fit {
    let degree = min(FIT_DEGREE, 3u);
    let n = coefficient_count(degree);
    let inv_h = 1.0 / h;
    let h2 = h * h;
    // A = Σ w m mᵀ accumulates in registers, as blocks over the monomials split into vectors
    // m0 = (1, x, y, x²), m1 = (y², xy, x³, y³), m2 = (x²y, xy²): only constant indices, so
    // nothing spills to per-thread memory in the loop (entry (row r, column c) gains
    // (w m_c) m_r, the same products as fit.rs). Cubic blocks only for cubic fits.
    var a00 = mat4x4<f32>();
    var a10 = mat4x4<f32>();
    var a11 = mat4x4<f32>();
    var a20 = mat4x2<f32>();
    var a21 = mat4x2<f32>();
    var a22 = mat2x2<f32>();
    var b0 = vec4<f32>(0.0);
    var b1 = vec4<f32>(0.0);
    var b2 = vec2<f32>(0.0);
    var total = 0.0;
    var cursor = first_neighbours(nb);
    loop {
        let j = next_neighbour(nb, &cursor);
        if j == NO_NEIGHBOUR {
            break;
        }
        let q = points_at(j).position - r;
        let w = weight(length_squared(q), h2);
        if !(w > 0.0) {
            continue;
        }
        let l = to_local(frame, q) * inv_h;
        let x = l.x;
        let y = l.y;
        let m0 = vec4<f32>(1.0, x, y, x * x);
        let m1 = vec4<f32>(y * y, x * y, x * x * x, y * y * y);
        let w0 = w * m0;
        let w1 = w * m1;
        total += w;
        a00 += mat4x4<f32>(m0 * w0.x, m0 * w0.y, m0 * w0.z, m0 * w0.w);
        a10 += mat4x4<f32>(m1 * w0.x, m1 * w0.y, m1 * w0.z, m1 * w0.w);
        a11 += mat4x4<f32>(m1 * w1.x, m1 * w1.y, m1 * w1.z, m1 * w1.w);
        b0 += w0 * l.z;
        b1 += w1 * l.z;
        if degree >= 3u {
            let m2 = vec2<f32>(x * x * y, x * y * y);
            let w2 = w * m2;
            a20 += mat4x2<f32>(m2 * w0.x, m2 * w0.y, m2 * w0.z, m2 * w0.w);
            a21 += mat4x2<f32>(m2 * w1.x, m2 * w1.y, m2 * w1.z, m2 * w1.w);
            a22 += mat2x2<f32>(m2 * w2.x, m2 * w2.y);
            b2 += w2 * l.z;
        }
    }
    var failed: Fit;
    failed.ok = false;
    failed.degraded = false;
    failed.poly.degree = 0u;
    if !(total > 0.0) {
        return failed;
    }
    // Unpacked into the packed lower triangle the factorisation overwrites in place (55
    // entries, not 100: private memory is scarce per invocation), divided by Σθ.
    let inv_total = 1.0 / total;
    var a: array<f32, 55>;
    var b: array<f32, 10>;
    for (var c = 0u; c < 4u; c++) {
        b[c] = b0[c] * inv_total;
        b[c + 4u] = b1[c] * inv_total;
        for (var row = c; row < 4u; row++) {
            a[tri(row, c)] = a00[c][row] * inv_total;
            a[tri(row + 4u, c + 4u)] = a11[c][row] * inv_total;
        }
        for (var row = 0u; row < 4u; row++) {
            a[tri(row + 4u, c)] = a10[c][row] * inv_total;
        }
        for (var row = 0u; row < 2u; row++) {
            a[tri(row + 8u, c)] = a20[c][row] * inv_total;
            a[tri(row + 8u, c + 4u)] = a21[c][row] * inv_total;
        }
    }
    for (var c = 0u; c < 2u; c++) {
        b[c + 8u] = b2[c] * inv_total;
        for (var row = c; row < 2u; row++) {
            a[tri(row + 8u, c + 8u)] = a22[c][row] * inv_total;
        }
    }
    // LDLᵀ without pivoting, stopping at the first bad pivot (ldlt): D on the diagonal, L
    // below it.
    var rank = n;
    for (var j = 0u; j < n; j++) {
        let ajj = a[tri(j, j)];
        var dj = ajj;
        for (var k = 0u; k < j; k++) {
            let ljk = a[tri(j, k)];
            dj = dj - ljk * ljk * a[tri(k, k)];
        }
        if !(dj > PIVOT_TOLERANCE * ajj) || !finite(dj) {
            rank = j;
            break;
        }
        a[tri(j, j)] = dj;
        for (var i = j + 1u; i < n; i++) {
            var s = a[tri(i, j)];
            for (var k = 0u; k < j; k++) {
                s = s - a[tri(i, k)] * a[tri(j, k)] * a[tri(k, k)];
            }
            a[tri(i, j)] = s / dj;
        }
    }
    // The highest degree whose coefficients all have good pivots.
    var used = 0u;
    var any = false;
    for (var g = 0u; g <= degree; g++) {
        if coefficient_count(g) <= rank {
            used = g;
            any = true;
        }
    }
    if !any {
        return failed;
    }
    let m = coefficient_count(used);
    for (var i = 0u; i < m; i++) {
        var s = b[i];
        for (var k = 0u; k < i; k++) {
            s = s - a[tri(i, k)] * b[k];
        }
        b[i] = s;
    }
    for (var i = 0u; i < m; i++) {
        b[i] = b[i] / a[tri(i, i)];
    }
    var out: Fit;
    out.ok = true;
    out.degraded = used != degree;
    out.poly.degree = used;
    for (var ii = 0u; ii < m; ii++) {
        let i = m - 1u - ii;
        var s = b[i];
        for (var k = i + 1u; k < m; k++) {
            s = s - a[tri(k, i)] * out.poly.c[k];
        }
        out.poly.c[i] = s;
    }
    return out;
}

