// Meridian radial distance (paper §III, closed form: see src/model/distance.rs), its
// analytic derivatives, and per-candidate reduction to Gauss-Newton normal equations.
//
// One dispatch evaluates every (point, candidate) pair: workgroup (gx, k) handles a
// grid-strided share of candidate k's points. Each candidate names its own range of the
// point buffer, so a batch of clouds (several point sets uploaded together) is fitted in
// the same dispatches as the starts of one cloud. Points arrive centred and scaled by
// the host, so f32 keeps its precision. Powers are exp2(e·log2|x|) with guards: f64
// transcendental functions are unreliable on lavapipe (wgpu issue 6087), and WGSL's pow
// is undefined for x <= 0.
//
// Parameter order of the 12-column Jacobian:
//   a1 a2 a3 a4 eps1 eps2 | tx ty tz | dx dy dz
// where (dx, dy, dz) is a rotation increment applied on the right, R <- R·exp([d]x), so
// the canonical point q = R^T (p - t) moves by q x d.

struct Params {
    // the residual kernel's output stride per candidate (the largest point range)
    n_points: u32,
    n_candidates: u32,
    // 0 squared, 1 Huber, 2 Cauchy
    loss: u32,
    // number of workgroups along x per candidate (the partial sums the host adds up)
    groups_x: u32,
    loss_scale: f32,
    _pad0: f32,
    _pad1: f32,
    _pad2: f32,
}

struct Candidate {
    // columns of R (canonical -> world), so q = (dot(c0, p - t), dot(c1, p - t), dot(c2, p - t))
    c0: vec4<f32>,
    c1: vec4<f32>,
    c2: vec4<f32>,
    t: vec4<f32>,
    // a1 a2 a3 a4
    a: vec4<f32>,
    // eps1 eps2
    e: vec2<f32>,
    // the candidate's points: points[first .. first + count]
    first: u32,
    count: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// xyz; w = 1 for a surface point, 2 for a free-space point (known to lie outside the
// object: its residual is min(r, 0), and it adds to the cost but not to the count), 0 for
// padding
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> candidates: array<Candidate>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;

const WG: u32 = 32u;
// 78 upper-triangle JtWJ entries, 12 JtWr, cost, count
const NE: u32 = 92u;
const NJ: u32 = 12u;

// |x|^e for x >= 0 (0 at 0), as exp2(e·log2 x).
fn pow0(x: f32, e: f32) -> f32 {
    if (x <= 0.0) {
        return 0.0;
    }
    return exp2(e * log2(x));
}

// Superellipse norm (|u|^(2/eps) + |v|^(2/eps))^(eps/2), scaled by the larger component.
fn se_norm(u: f32, v: f32, eps: f32) -> f32 {
    let au = abs(u);
    let av = abs(v);
    let m = max(au, av);
    if (m <= 0.0) {
        return 0.0;
    }
    let k = 2.0 / eps;
    return m * pow0(pow0(au / m, k) + pow0(av / m, k), eps * 0.5);
}

// (dM/du, dM/dv, dM/deps) of M = se_norm(u, v, eps), given M.
fn se_norm_partials(u: f32, v: f32, m: f32, eps: f32) -> vec3<f32> {
    if (m <= 0.0) {
        return vec3<f32>(0.0);
    }
    let k = 2.0 / eps;
    let tu = abs(u) / m;
    let tv = abs(v) / m;
    var du = 0.0;
    var dv = 0.0;
    var lsum = 0.0;
    if (tu > 0.0) {
        let tk = pow0(tu, k);
        du = sign(u) * tk / tu;
        lsum += tk * log(tu);
    }
    if (tv > 0.0) {
        let tk = pow0(tv, k);
        dv = sign(v) * tk / tv;
        lsum += tk * log(tv);
    }
    return vec3<f32>(du, dv, -(m / eps) * lsum);
}

struct Eval {
    r: f32,
    // dr/dq in the canonical frame
    dq: vec3<f32>,
    // dr/d(a1, a2, a3, a4)
    da: vec4<f32>,
    // dr/d(eps1, eps2)
    de: vec2<f32>,
}

// Signed meridian residual of canonical point q and (optionally) its gradient.
fn meridian(q: vec3<f32>, a: vec4<f32>, e: vec2<f32>, with_gradient: bool) -> Eval {
    var ev: Eval;
    ev.dq = vec3<f32>(0.0);
    ev.da = vec4<f32>(0.0);
    ev.de = vec2<f32>(0.0);
    let rho = length(q.xy);
    var dir = vec2<f32>(1.0, 0.0);
    if (rho > 1e-30) {
        dir = q.xy / rho;
    }
    // s = rho / G = 1 / G(dir): the section size in this direction (a_omega_s)
    let s = 1.0 / se_norm(dir.x / a.x, dir.y / a.y, e.y);
    let g = rho / s;
    let bx = g - a.w;
    let bz = q.z / a.z;
    let n = se_norm(bx, bz, e.x);
    let l = length(vec2<f32>(s * bx, q.z));
    var ux = 1.0;
    var uz = 0.0;
    if (n > 0.0) {
        ux = bx / n;
        uz = bz / n;
    }
    let reach = length(vec2<f32>(s * ux, a.z * uz));
    ev.r = l - reach;
    if (!with_gradient || n < 1e-6 || l <= 0.0) {
        return ev;
    }
    let r_l = 1.0 - 1.0 / n;
    let r_n = l / (n * n);
    let l_s = s * bx * bx / l;
    let l_x = s * s * bx / l;
    let l_z = q.z / l;
    let np = se_norm_partials(bx, bz, n, e.x);
    let u = q.x / a.x;
    let v = q.y / a.y;
    var gp = vec3<f32>(0.0);
    if (g > 0.0) {
        gp = se_norm_partials(u, v, g, e.y);
    }
    let g_x = gp.x / a.x;
    let g_y = gp.y / a.y;
    let g_a1 = -gp.x * u / a.x;
    let g_a2 = -gp.y * v / a.y;
    let g_e2 = gp.z;
    var s_x = 0.0;
    var s_y = 0.0;
    var s_scale = 0.0;
    if (g > 1e-6) {
        s_x = (dir.x - s * g_x) / g;
        s_y = (dir.y - s * g_y) / g;
    }
    if (g > 0.0) {
        s_scale = -s / g;
    }
    let c_s = r_l * l_s;
    let c_g = r_l * l_x + r_n * np.x;
    ev.dq = vec3<f32>(c_s * s_x + c_g * g_x, c_s * s_y + c_g * g_y, r_l * l_z + r_n * np.y / a.z);
    ev.da = vec4<f32>(
        c_s * s_scale * g_a1 + c_g * g_a1,
        c_s * s_scale * g_a2 + c_g * g_a2,
        -r_n * np.y * bz / a.z,
        -c_g,
    );
    ev.de = vec2<f32>(r_n * np.z, c_s * s_scale * g_e2 + c_g * g_e2);
    return ev;
}

fn canonical(c: Candidate, p: vec3<f32>) -> vec3<f32> {
    let d = p - c.t.xyz;
    return vec3<f32>(dot(c.c0.xyz, d), dot(c.c1.xyz, d), dot(c.c2.xyz, d));
}

// Whether q (canonical) lies beyond the candidate's bounding box, |x| <= a1(1+a4),
// |y| <= a2(1+a4), |z| <= a3, and so outside the solid.
fn beyond_the_box(c: Candidate, q: vec3<f32>) -> bool {
    let half = vec3<f32>(c.a.x * (1.0 + c.a.w), c.a.y * (1.0 + c.a.w), c.a.z);
    return any(abs(q) > half);
}

// The residual of a point of kind w (see `points`): a free-space point counts only inside.
fn residual_of(r: f32, w: f32) -> f32 {
    if (w == 2.0) {
        return min(r, 0.0);
    }
    return r;
}

// Robust loss: (cost rho(r), IRLS weight rho'(r)/r).
fn loss_of(r: f32) -> vec2<f32> {
    let k = params.loss_scale;
    if (params.loss == 1u) {
        let ar = abs(r);
        if (ar <= k) {
            return vec2<f32>(0.5 * r * r, 1.0);
        }
        return vec2<f32>(k * ar - 0.5 * k * k, k / ar);
    }
    if (params.loss == 2u) {
        let t = r / k;
        return vec2<f32>(0.5 * k * k * log(1.0 + t * t), 1.0 / (1.0 + t * t));
    }
    return vec2<f32>(0.5 * r * r, 1.0);
}

fn finite(x: f32) -> bool {
    // NaN fails both comparisons; the bound catches infinities
    return abs(x) <= 3.0e38;
}

// ---- residuals: out[k * n_points + i] = r_i(candidate k), i < count of k ------------

@compute @workgroup_size(64)
fn residuals(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    let k = gid.y;
    if (k >= params.n_candidates) {
        return;
    }
    let c = candidates[k];
    if (i >= c.count) {
        return;
    }
    let p = points[c.first + i];
    let ev = meridian(canonical(c, p.xyz), c.a, c.e, false);
    out[k * params.n_points + i] = residual_of(ev.r, p.w);
}

// ---- normal equations: out[(k * groups_x + gx) * (NE + 1) + j] ----------------------
// The extra value of each partial is a completion marker (1.0): the host clears the
// output before the dispatch and rejects a result whose markers are missing, so a
// dispatch the driver dropped can never pass for a result.

var<workgroup> partial: array<f32, 2944>; // WG * NE

@compute @workgroup_size(32)
fn normal_equations(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let k = wid.y;
    let c = candidates[k];
    var acc: array<f32, 92>;
    for (var j = 0u; j < NE; j++) {
        acc[j] = 0.0;
    }
    let stride = params.groups_x * WG;
    for (var i = wid.x * WG + lid.x; i < c.count; i += stride) {
        let p = points[c.first + i];
        if (p.w == 0.0) {
            continue;
        }
        let q = canonical(c, p.xyz);
        // a free-space point beyond the bounding box is outside: no residual, told
        // without its distance
        if (p.w == 2.0 && beyond_the_box(c, q)) {
            continue;
        }
        let ev = meridian(q, c.a, c.e, true);
        // translation: dq/dt = -R^T, so dr/dt = -R dr/dq; rotation increment: dr/dd = dr/dq x q
        let dt = -(c.c0.xyz * ev.dq.x + c.c1.xyz * ev.dq.y + c.c2.xyz * ev.dq.z);
        let dd = cross(ev.dq, q);
        var jac = array<f32, 12>(ev.da.x, ev.da.y, ev.da.z, ev.da.w, ev.de.x, ev.de.y, dt.x, dt.y, dt.z, dd.x, dd.y, dd.z);
        var ok = finite(ev.r);
        for (var a = 0u; a < NJ; a++) {
            ok = ok && finite(jac[a]);
        }
        let r = residual_of(ev.r, p.w);
        // a free-space point outside the candidate has no residual and no gradient
        if (!ok || (p.w == 2.0 && r == 0.0)) {
            continue;
        }
        let lw = loss_of(r);
        var idx = 0u;
        for (var a = 0u; a < NJ; a++) {
            let wa = lw.y * jac[a];
            for (var b = a; b < NJ; b++) {
                acc[idx] += wa * jac[b];
                idx++;
            }
            acc[78u + a] += wa * r;
        }
        acc[90] += lw.x;
        acc[91] += select(1.0, 0.0, p.w == 2.0);
    }
    let base = lid.x * NE;
    for (var j = 0u; j < NE; j++) {
        partial[base + j] = acc[j];
    }
    workgroupBarrier();
    // tree reduction over the workgroup's rows, the adds of each level spread over all threads
    for (var half = WG / 2u; half > 0u; half = half / 2u) {
        for (var idx = lid.x; idx < half * NE; idx += WG) {
            partial[idx] += partial[idx + half * NE];
        }
        workgroupBarrier();
    }
    let o = (k * params.groups_x + wid.x) * (NE + 1u);
    for (var j = lid.x; j < NE; j += WG) {
        out[o + j] = partial[j];
    }
    if (lid.x == 0u) {
        out[o + NE] = 1.0;
    }
}

// ---- costs only (line searches): out[(k * groups_x + gx) * 3 + {cost, count, marker}] --

var<workgroup> partial_cost: array<vec2<f32>, 32>;

@compute @workgroup_size(32)
fn costs(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let k = wid.y;
    let c = candidates[k];
    var acc = vec2<f32>(0.0);
    let stride = params.groups_x * WG;
    for (var i = wid.x * WG + lid.x; i < c.count; i += stride) {
        let p = points[c.first + i];
        if (p.w == 0.0) {
            continue;
        }
        let q = canonical(c, p.xyz);
        // (a free-space point beyond the bounding box adds nothing)
        if (p.w == 2.0 && beyond_the_box(c, q)) {
            continue;
        }
        let ev = meridian(q, c.a, c.e, false);
        if (finite(ev.r)) {
            acc += vec2<f32>(loss_of(residual_of(ev.r, p.w)).x, select(1.0, 0.0, p.w == 2.0));
        }
    }
    partial_cost[lid.x] = acc;
    workgroupBarrier();
    for (var half = WG / 2u; half > 0u; half = half / 2u) {
        if (lid.x < half) {
            partial_cost[lid.x] += partial_cost[lid.x + half];
        }
        workgroupBarrier();
    }
    if (lid.x == 0u) {
        let o = (k * params.groups_x + wid.x) * 3u;
        out[o] = partial_cost[0].x;
        out[o + 1u] = partial_cost[0].y;
        out[o + 2u] = 1.0;
    }
}
