// The fit's objective (src/fit/objective): the log-likelihood of each point under the
// blurred surface, its gradient and the BHHH outer product, summed per workgroup.
//
//   p(x) = inlier · W(x) · sum over surface elements of weight · (N(x; s, sigma²) - floor)
//          + outlier density
//
// The host builds the quadrature at the candidate (section nodes times sweep samples,
// their derivatives, and which normaliser cells the sensor sees) and the normaliser's
// constants; each invocation takes one point, visits the window of the quadrature within
// the cutoff and writes ln p and its 13 partials (a1 a2 a3 a4 eps1 eps2 | t | turn on
// the left | ln sigma). The host finishes the partial sums in f64 and negates.

struct Params {
    n_points: u32,
    n_nodes: u32,
    n_sweep: u32,
    // workgroups along x (the partial sums the host adds up)
    groups_x: u32,
    // 1: the gradient and outer product; 2: a sensor (points carry range weights);
    // 4: the visibility of the normaliser's cells is held
    flags: u32,
    // the normaliser's sectors per ring (the visibility's row length)
    sectors: u32,
    _pad0: u32,
    _pad1: u32,
    // the rotation's columns (canonical -> world), the translation, the viewpoint
    c0: vec4<f32>,
    c1: vec4<f32>,
    c2: vec4<f32>,
    t: vec4<f32>,
    viewpoint: vec4<f32>,
    // a1 a2 a3 a4
    a: vec4<f32>,
    // sigma², the cutoff distance, the kernel's floor, (1 - w)·(2 pi sigma²)^-3/2 / A
    kernel: vec4<f32>,
    // the outliers' density
    outlier: vec4<f32>,
    // d ln A / d (shape, translation, turn)
    d_log_area: array<vec4<f32>, 3>,
}

@group(0) @binding(0) var<uniform> params: Params;
// xyz and the point's range weight
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
// per section node: (c, w, dc, dw), halves (tc0, tw0, tc1, tw1), their eps1-derivatives
@group(0) @binding(2) var<storage, read> nodes: array<vec4<f32>>;
// per sweep sample: (cx, cy, dx, dy), their eps2-derivatives, (C x D, polar angle, radius, 0)
@group(0) @binding(3) var<storage, read> sweep: array<vec4<f32>>;
// rings of the nodes, sectors of the samples, then the visibility of each cell
@group(0) @binding(4) var<storage, read> cells: array<u32>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;

const WG: u32 = 32u;
// ln p, 13 partials, 91 upper-triangle products
const NV: u32 = 105u;
const NP: u32 = 13u;
const TAU: f32 = 6.283185307179586;

struct Sums {
    sum: f32,
    shape: array<f32, 6>,
    ln_sigma: f32,
    by_point: vec3<f32>,
    by_sight: vec3<f32>,
}

fn rem_tau(x: f32) -> f32 {
    return x - floor(x / TAU) * TAU;
}

// The first sweep sample at or past `angle` counted on from sample 0 (whole turns add
// n_sweep each): the samples' polar angles rise in [0, 2 pi).
fn first_at(angle: f32) -> i32 {
    let turns = floor(angle / TAU);
    let a = angle - turns * TAU;
    var lo = 0u;
    var hi = params.n_sweep;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (sweep[3u * mid + 2u].y < a) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return i32(lo) + i32(turns) * i32(params.n_sweep);
}

fn sees(k: u32, m: u32) -> bool {
    if ((params.flags & 4u) == 0u) {
        return true;
    }
    let ring = cells[k];
    let sector = cells[params.n_nodes + m];
    return cells[params.n_nodes + params.n_sweep + ring * params.sectors + sector] != 0u;
}

// The kernel sum of canonical point q (seen along canonical v) with its partials: the
// CPU's `Window::sums`, term for term.
fn point_sums(q: vec3<f32>, v: vec3<f32>, has_sight: bool, gradient: bool) -> Sums {
    var s: Sums;
    s.sum = 0.0;
    for (var p = 0u; p < 6u; p++) {
        s.shape[p] = 0.0;
    }
    s.ln_sigma = 0.0;
    s.by_point = vec3<f32>(0.0);
    s.by_sight = vec3<f32>(0.0);
    let a1 = params.a.x;
    let a2 = params.a.y;
    let a3 = params.a.z;
    let a4 = params.a.w;
    let var_ = params.kernel.x;
    let cut = params.kernel.y;
    let floor_ = params.kernel.z;
    let cut2 = cut * cut;
    let count = params.n_sweep;
    let rho = length(q.xy);
    let sight_length = max(length(v), 1e-30);
    var first = 0u;
    var span = count;
    if (rho > cut) {
        let half = asin(cut / rho);
        let polar = rem_tau(atan2(q.y, q.x));
        let lo = first_at(polar - half);
        let hi = first_at(polar + half);
        span = min(u32(max(hi - lo, 0)), count);
        let c = i32(count);
        first = u32(((lo % c) + c) % c);
    }
    let end0 = min(count, first + span);
    let end1 = select(0u, first + span - count, first + span > count);
    var r_lo = 3.0e38;
    var r_hi = 0.0;
    for (var m = first; m < end0; m++) {
        let r = sweep[3u * m + 2u].z;
        r_lo = min(r_lo, r);
        r_hi = max(r_hi, r);
    }
    for (var m = 0u; m < end1; m++) {
        let r = sweep[3u * m + 2u].z;
        r_lo = min(r_lo, r);
        r_hi = max(r_hi, r);
    }
    for (var k = 0u; k < params.n_nodes; k++) {
        let node = nodes[3u * k];
        let c = node.x;
        let w = node.y;
        let lambda = a4 + c;
        if (lambda <= 0.0) {
            continue;
        }
        let dz = q.z - a3 * w;
        if (dz * dz >= cut2) {
            continue;
        }
        let gap = max(max(lambda * r_lo - rho, rho - lambda * r_hi), 0.0);
        if (gap * gap + dz * dz >= cut2) {
            continue;
        }
        let halves = nodes[3u * k + 1u];
        let d_halves = nodes[3u * k + 2u];
        for (var step = 0u; step < span; step++) {
            var m = first + step;
            if (m >= count) {
                m = m - count;
            }
            let sample = sweep[3u * m];
            let cx = sample.x;
            let cy = sample.y;
            let ex = q.x - lambda * cx;
            let ey = q.y - lambda * cy;
            let d2 = ex * ex + ey * ey + dz * dz;
            if (d2 >= cut2) {
                continue;
            }
            let dx = sample.z;
            let dy = sample.w;
            let cross_ = sweep[3u * m + 2u].x;
            // the element's weight: its area, or seen by the sensor its projected area,
            // half by half of the section's step
            var facing = vec2<f32>(0.0);
            var weight = 0.0;
            var areas = vec2<f32>(0.0);
            if (has_sight) {
                if (!sees(k, m)) {
                    continue;
                }
                let turn_ = dy * v.x - dx * v.y;
                facing = vec2<f32>(
                    a3 * halves.y * turn_ - halves.x * cross_ * v.z,
                    a3 * halves.w * turn_ - halves.z * cross_ * v.z,
                );
                let projected = max(-facing.x, 0.0) + max(-facing.y, 0.0);
                if (projected <= 0.0) {
                    continue;
                }
                weight = lambda * projected / sight_length;
            } else {
                let dd = dx * dx + dy * dy;
                areas = vec2<f32>(
                    sqrt(a3 * a3 * halves.y * halves.y * dd + halves.x * halves.x * cross_ * cross_),
                    sqrt(a3 * a3 * halves.w * halves.w * dd + halves.z * halves.z * cross_ * cross_),
                );
                weight = lambda * (areas.x + areas.y);
            }
            let gauss = exp(-0.5 * d2 / var_);
            let term = weight * (gauss - floor_);
            s.sum += term;
            if (!gradient) {
                continue;
            }
            let slope = weight * gauss / var_;
            s.by_point -= slope * vec3<f32>(ex, ey, dz);
            let dc = node.z;
            let dw = node.w;
            let dsample = sweep[3u * m + 1u];
            let dcx = dsample.x;
            let dcy = dsample.y;
            let ddx = dsample.z;
            let ddy = dsample.w;
            let radial = ex * cx + ey * cy;
            var by_shape = array<f32, 6>(
                ex * lambda * cx / a1,
                ey * lambda * cy / a2,
                dz * w,
                radial,
                radial * dc + dz * a3 * dw,
                lambda * (ex * dcx + ey * dcy),
            );
            s.ln_sigma += slope * d2;
            var lw = array<f32, 6>(0.0, 0.0, 0.0, 1.0 / lambda, dc / lambda, 0.0);
            let d_cross = dcx * dy + cx * ddy - dcy * dx - cy * ddx;
            for (var h = 0u; h < 2u; h++) {
                let tc = select(halves.x, halves.z, h == 1u);
                let tw = select(halves.y, halves.w, h == 1u);
                let dtc = select(d_halves.x, d_halves.z, h == 1u);
                let dtw = select(d_halves.y, d_halves.w, h == 1u);
                if (has_sight) {
                    let f = select(facing.x, facing.y, h == 1u);
                    if (f >= 0.0) {
                        continue;
                    }
                    let total = max(-facing.x, 0.0) + max(-facing.y, 0.0);
                    let per = -1.0 / total;
                    let turn_ = dy * v.x - dx * v.y;
                    lw[0] += (a3 * tw * (-dx * v.y) - tc * cross_ * v.z) / a1 * per;
                    lw[1] += (a3 * tw * (dy * v.x) - tc * cross_ * v.z) / a2 * per;
                    lw[2] += tw * turn_ * per;
                    lw[4] += (a3 * dtw * turn_ - dtc * cross_ * v.z) * per;
                    lw[5] += (a3 * tw * (ddy * v.x - ddx * v.y) - tc * d_cross * v.z) * per;
                    s.by_sight += term * vec3<f32>(a3 * tw * dy, -a3 * tw * dx, -tc * cross_) * per;
                } else {
                    let area = select(areas.x, areas.y, h == 1u);
                    if (area == 0.0) {
                        continue;
                    }
                    let per = 1.0 / (area * (areas.x + areas.y));
                    let dd = dx * dx + dy * dy;
                    let cc = cross_ * cross_;
                    lw[0] += (a3 * a3 * tw * tw * dx * dx + tc * tc * cc) / a1 * per;
                    lw[1] += (a3 * a3 * tw * tw * dy * dy + tc * tc * cc) / a2 * per;
                    lw[2] += a3 * tw * tw * dd * per;
                    lw[4] += (a3 * a3 * tw * dtw * dd + tc * dtc * cc) * per;
                    lw[5] += (a3 * a3 * tw * tw * (dx * ddx + dy * ddy) + tc * tc * cross_ * d_cross) * per;
                }
            }
            for (var p = 0u; p < 6u; p++) {
                s.shape[p] += slope * by_shape[p] + term * lw[p];
            }
        }
    }
    return s;
}

var<workgroup> partial: array<f32, 3360>; // WG * NV

// out[gx * (NV + 1) + j]: the workgroup's sums of ln p, its partials and their products,
// and a completion marker (1.0) the host checks.
@compute @workgroup_size(32)
fn likelihood(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    var acc: array<f32, 105>;
    for (var j = 0u; j < NV; j++) {
        acc[j] = 0.0;
    }
    let gradient = (params.flags & 1u) != 0u;
    let has_sight = (params.flags & 2u) != 0u;
    let c0 = params.c0.xyz;
    let c1 = params.c1.xyz;
    let c2 = params.c2.xyz;
    let stride = params.groups_x * WG;
    for (var i = wid.x * WG + lid.x; i < params.n_points; i += stride) {
        let p = points[i];
        let x = p.xyz;
        let d = x - params.t.xyz;
        let q = vec3<f32>(dot(c0, d), dot(c1, d), dot(c2, d));
        let seen = x - params.viewpoint.xyz;
        let v = vec3<f32>(dot(c0, seen), dot(c1, seen), dot(c2, seen));
        let s = point_sums(q, v, has_sight, gradient);
        let weight = select(1.0, p.w, has_sight);
        let density = params.kernel.w * weight * s.sum + params.outlier.x;
        acc[0] += log(density);
        if (!gradient) {
            continue;
        }
        let f = params.kernel.w * weight / density;
        var g: array<f32, 13>;
        for (var k = 0u; k < 6u; k++) {
            g[k] = s.shape[k];
        }
        let by_point = c0 * s.by_point.x + c1 * s.by_point.y + c2 * s.by_point.z;
        g[6] = -by_point.x;
        g[7] = -by_point.y;
        g[8] = -by_point.z;
        var turn_ = cross(by_point, d);
        if (has_sight) {
            let by_sight = c0 * s.by_sight.x + c1 * s.by_sight.y + c2 * s.by_sight.z;
            turn_ += cross(by_sight, seen);
        }
        g[9] = turn_.x;
        g[10] = turn_.y;
        g[11] = turn_.z;
        g[12] = s.ln_sigma - 3.0 * s.sum;
        let share = f * s.sum;
        for (var k = 0u; k < NP; k++) {
            g[k] *= f;
        }
        for (var k = 0u; k < 12u; k++) {
            g[k] -= share * params.d_log_area[k / 4u][k % 4u];
        }
        var idx = NP + 1u;
        for (var a = 0u; a < NP; a++) {
            acc[1u + a] += g[a];
            for (var b = a; b < NP; b++) {
                acc[idx] += g[a] * g[b];
                idx++;
            }
        }
    }
    let base = lid.x * NV;
    for (var j = 0u; j < NV; j++) {
        partial[base + j] = acc[j];
    }
    workgroupBarrier();
    for (var half = WG / 2u; half > 0u; half = half / 2u) {
        for (var idx = lid.x; idx < half * NV; idx += WG) {
            partial[idx] += partial[idx + half * NV];
        }
        workgroupBarrier();
    }
    let o = wid.x * (NV + 1u);
    for (var j = lid.x; j < NV; j += WG) {
        out[o + j] = partial[j];
    }
    if (lid.x == 0u) {
        out[o + NV] = 1.0;
    }
}
