"""Compiled (numba) kernel of the multi-segment elastic catenary with seabed friction.

Not public: `models.catenary` wraps it. One line = segments in series from anchor (index 0) to
fairlead, with point loads at the joints. Unknowns are the horizontal tension H (constant along
the suspended part, no drag) and the fairlead vertical tension VF; the residuals are the span
and height mismatches. The formulation is the classic elastic catenary (seed 001 eqs 1-3 and
seed 003's end forces, extended with axial compliance and Jonkman's seabed-friction model as
used by MoorPy), written with difference quotients so that no term divides by the weight:
a weightless or nearly weightless segment is a straight line, not 0/0.

Per suspended piece of unstretched length l, weight w, compliance c = 1/EA, with a = Vtop/H,
b = Vbottom/H = a - w l / H, Sa = sqrt(1 + a^2):
    dx = l * (asinh a - asinh b)/(a - b) + c H l
    dz = l * (Sa - Sb)/(a - b)          + c l (Vtop + Vbottom)/2
which is (H/w)(asinh a - asinh b) and (H/w)(Sa - Sb) for w != 0.
"""

from __future__ import annotations

import math

import numpy as np

from models._jit import kernel

# regime codes (mirrored as names in models.catenary.REGIMES)
SUSPENDED = 0
GROUNDED = 1  # part of the line on the seabed, tension at the anchor > 0
GROUNDED_SLACK_ANCHOR = 2  # friction takes all the tension before the anchor
SLACK_PILED = 3  # H = 0: vertical hanging part, the rest lies slack on the seabed
ON_SEABED = 4  # fairlead on the seabed, the whole line lies on it

OK = 0
NOT_CONVERGED = 1
OFF_SEABED_MODEL = 2  # equilibrium found, but it would need seabed contact not modelled

_SMALL = 1e-6
# np.hypot, not math.hypot, in the kernels: compiled both are libm's hypot, but Python's own
# math.hypot differs from it in the last bit (0.1 % of inputs), so run as plain Python a
# kernel would not give the compiled bits; numpy's is libm's


@kernel()
def _quotients(a: float, b: float):
    """Difference quotients g1 = (asinh a - asinh b)/(a-b), g2 = (Sa-Sb)/(a-b),
    e1 = (a/Sa - b/Sb)/(a-b), e2 = (1/Sa - 1/Sb)/(a-b), stable for a -> b."""
    sa = np.hypot(1.0, a)
    sb = np.hypot(1.0, b)
    g2 = (a + b) / (sa + sb)
    e2 = -g2 / (sa * sb)
    if a * b > 0.0:
        aa = abs(a)
        bb = abs(b)
        den = aa * sb + bb * sa
        k = (aa + bb) / den
        d = aa - bb
        y = d * k  # asinh(aa) - asinh(bb) = asinh(y), exact identity
        if abs(y) < _SMALL:
            g1 = k * (1.0 - y * y / 6.0)
        else:
            g1 = math.asinh(y) / d
        e1 = (a + b) / ((a * sb + b * sa) * sa * sb)
    else:
        d = a - b
        if d == 0.0:  # both zero
            g1 = 1.0
            e1 = 1.0
        else:
            g1 = (math.asinh(a) - math.asinh(b)) / d
            e1 = (a / sa - b / sb) / d
    return g1, g2, e1, e2, sa, sb


@kernel()
def piece(h: float, vt: float, w: float, length: float, c: float):
    """Span, height and their partials (d/dH, d/dVtop) of one fully suspended piece."""
    a = vt / h
    b = (vt - w * length) / h
    g1, g2, e1, e2, sa, sb = _quotients(a, b)
    lh = length / h
    dx = length * g1 + c * h * length
    dz = length * g2 + c * length * (vt - 0.5 * w * length)
    dx_dh = lh * (g1 - e1) + c * length
    dx_dv = lh * e2
    dz_dh = -lh * g2 / (sa * sb)
    dz_dv = lh * e1 + c * length
    return dx, dz, dx_dh, dx_dv, dz_dh, dz_dv


@kernel()
def _heavy_prefix(seg_w, joint_p) -> int:
    """Number of segments from the anchor that may lie on the seabed: all heavy, with no float
    at the joints between them (segments 0 .. n-1)."""
    n_heavy = 0
    for k in range(seg_w.shape[0]):
        if seg_w[k] <= 0.0:
            break
        n_heavy = k + 1
        if k < seg_w.shape[0] - 1 and joint_p[k] < 0.0:
            break
    return n_heavy


@kernel()
def evaluate(h, vf, x, z, seg_l, seg_w, seg_c, joint_p, mu, seabed, joint_h, joint_v):
    """Residuals (span, height), Jacobian d(span, height)/d(H, VF) and end forces.

    Seabed contact is modelled on the heavy part of the line next to the anchor (all segments
    and joint loads from the anchor up to the touchdown weigh >= 0), where V < 0 at the anchor
    means the line would dig in. Fills joint_h/joint_v (tension components just above each
    joint, in the upper segment). Returns rx, rz, jxh, jxv, jzh, jzv, h_anchor, v_anchor,
    grounded_length, regime, valid; valid is False when the configuration is not physical on
    this seabed: a buoyant anchor segment pulled down into it, or a mid-line sag (V changing
    sign in a heavy segment) below it.
    """
    n = seg_l.shape[0]
    n_heavy = _heavy_prefix(seg_w, joint_p) if seabed else 0
    sx = 0.0
    sz = 0.0
    jxh = 0.0
    jxv = 0.0
    jzh = 0.0
    jzv = 0.0
    vt = vf
    valid = True
    k_td = -1  # segment holding the touchdown point
    l_susp = 0.0
    for k in range(n - 1, -1, -1):
        w = seg_w[k]
        vb = vt - w * seg_l[k]
        if k < n_heavy and vb < 0.0:
            k_td = k
            l_susp = vt / w if vt > 0.0 else 0.0
            break
        if seabed and w > 0.0 and vt > 0.0 and vb < 0.0:
            # lowest point of a mid-line sag: it must stay above the seabed
            a = vt / h
            sa = np.hypot(1.0, a)
            z_low = z - sz - (vt * a / (w * (sa + 1.0)) + 0.5 * seg_c[k] * vt * vt / w)
            if z_low < -1e-9 * (abs(z) + seg_l[k]):
                valid = False
        dx, dz, a1, a2, a3, a4 = piece(h, vt, w, seg_l[k], seg_c[k])
        sx += dx
        sz += dz
        jxh += a1
        jxv += a2
        jzh += a3
        jzv += a4
        if k > 0:
            joint_h[k - 1] = h
            joint_v[k - 1] = vb
            vt = vb - joint_p[k - 1]
    if k_td < 0:
        va = vt - seg_w[0] * seg_l[0]
        if seabed and va < 0.0:
            valid = False  # a buoyant anchor segment pulled down into the seabed
        return sx - x, sz - z, jxh, jxv, jzh, jzv, h, va, 0.0, SUSPENDED, valid
    # suspended piece of the touchdown segment, from the touchdown point (V = 0) up
    w = seg_w[k_td]
    c = seg_c[k_td]
    if l_susp > 0.0:
        a = vt / h
        sa = np.hypot(1.0, a)
        ash = math.asinh(a)
        sx += h / w * ash + c * h * l_susp
        sz += vt * a / (w * (sa + 1.0)) + 0.5 * c * vt * l_susp
        jxh += (ash - a / sa) / w + c * l_susp
        jxv += 1.0 / (w * sa) + c * h / w
        jzh += -(a * a / (sa + 1.0)) / (w * sa)
        jzv += a / (w * sa) + c * vt / w
    # grounded part: march from the touchdown to the anchor, friction lowering the tension.
    # vt < 0: the touchdown is pinned at the joint above segment k_td, whose point load the
    # seabed carries in part (reaction -vt, with its own friction); the grounded length then
    # does not move with VF
    pinned = vt < 0.0
    t = max(h + mu * vt, 0.0) if pinned else h
    grounded = seg_l[k_td] - l_susp
    stretch = 0.0
    pos_c = 0.0  # sum of c * length over the grounded material under tension
    for k in range(k_td, -1, -1):
        if k < k_td:
            p = joint_p[k]
            joint_h[k] = t
            joint_v[k] = 0.0
            t = max(t - mu * p, 0.0)
            g = seg_l[k]
            grounded += g
        else:
            g = seg_l[k] - l_susp
        if t <= 0.0 or g <= 0.0:
            continue
        ck = seg_c[k]
        drop = mu * seg_w[k] * g
        if drop <= t:
            stretch += ck * g * (t - 0.5 * drop)
            pos_c += ck * g
            t -= drop
        else:
            gp = t / (mu * seg_w[k])
            stretch += 0.5 * ck * t * gp
            pos_c += ck * gp
            t = 0.0
    sx += grounded + stretch
    jxh += pos_c
    jxv += mu * pos_c if pinned else -1.0 / w - c * h / w + mu * pos_c
    regime = GROUNDED if t > 0.0 else GROUNDED_SLACK_ANCHOR
    return sx - x, sz - z, jxh, jxv, jzh, jzv, t, 0.0, grounded, regime, valid


@kernel()
def _sinhc_minus_one(p: float) -> float:
    """sinh(p)/p - 1 without cancellation for small p."""
    if p < 1e-3:
        p2 = p * p
        return p2 / 6.0 * (1.0 + p2 / 20.0)
    return math.sinh(p) / p - 1.0


@kernel()
def _phi_from_excess(q: float) -> float:
    """Solve sinh(phi)/phi = 1 + q (q > 0) for phi > 0 (seed 003's transcendental equation,
    with q = r - 1 passed directly so that near-taut lines keep their precision)."""
    if q <= 0.0:
        return 1e-12
    if q < 2.0:
        p = math.sqrt(6.0 * q)
    else:
        r = 1.0 + q
        p = math.log(2.0 * r) + math.log(math.log(2.0 * r) + 1.0)
    lq = math.log1p(q)
    for _ in range(60):
        # Newton on ln(sinh p / p) = ln(1 + q): well scaled from tiny to huge p
        if p > 700.0:
            f = p - math.log(2.0 * p) - lq
            fp = 1.0 - 1.0 / p
        else:
            f = math.log1p(_sinhc_minus_one(p)) - lq
            fp = p / 3.0 * (1.0 - p * p / 15.0) if p < 1e-3 else 1.0 / math.tanh(p) - 1.0 / p
        p_new = p - f / fp
        if p_new <= 0.0:
            p_new = 0.5 * p
        if abs(p_new - p) <= 1e-15 * p:
            return p_new
        p = p_new
    return p


@kernel()
def _rise(v0: float, w: float, length: float, c: float) -> float:
    """Height gained along a vertical (H = 0) piece whose vertical tension runs from v0 to
    v0 + w length: the integral of sign(V) (1 + c |V|) ds (V < 0: the piece hangs down)."""
    v1 = v0 + w * length
    if v0 >= 0.0 and v1 >= 0.0:
        return length * (1.0 + 0.5 * c * (v0 + v1))
    if v0 <= 0.0 and v1 <= 0.0:
        return -length * (1.0 - 0.5 * c * (v0 + v1))
    s1 = -v0 / w  # where V changes sign
    s2 = length - s1
    return (math.copysign(s1 * (1.0 + 0.5 * c * abs(v0)), v0)
            + math.copysign(s2 * (1.0 + 0.5 * c * abs(v1)), v1))


@kernel()
def _column(lb, seg_l, seg_w, seg_c, joint_p):
    """Vertical (H = 0) line above a touchdown at unstretched distance lb from the anchor:
    returns (height of the fairlead, VF, lowest height reached, segment of the touchdown)."""
    n = seg_l.shape[0]
    start = 0.0
    z = 0.0
    z_min = 0.0
    v = 0.0
    k_td = -1
    for k in range(n):
        end = start + seg_l[k]
        if end <= lb and k < n - 1:
            start = end
            continue
        if k_td < 0:
            k_td = k
            ell = end - lb
        else:
            v += joint_p[k - 1]
            ell = seg_l[k]
        w = seg_w[k]
        if ell > 0.0:
            v1 = v + w * ell
            if v < 0.0 < v1:  # a trough inside the piece
                s1 = -v / w
                z_min = min(z_min, z - s1 * (1.0 - 0.5 * seg_c[k] * v))
            z += _rise(v, w, ell, seg_c[k])
            v = v1
            z_min = min(z_min, z)
        start = end
    return z, v, z_min, k_td


@kernel()
def slack_piled(x, z, seg_l, seg_w, seg_c, joint_p, n_heavy, joint_h, joint_v, out) -> bool:
    """H = 0 configuration: the heavy part next to the anchor lies slack on the seabed (longer
    than the span, so it piles up) and the rest stands vertically under the fairlead, folding
    where buoyant parts turn its vertical tension negative. Fills out[0:11] and returns True
    if this is the equilibrium, i.e. if a catenary with H > 0 cannot reach this close."""
    if n_heavy == 0:
        return False
    lmax = 0.0
    for k in range(n_heavy):
        lmax += seg_l[k]
    if x > lmax:
        return False
    # the column height falls as the grounded length lb grows; piled needs lb >= x
    lo = x
    hi = lmax
    f_lo = _column(lo, seg_l, seg_w, seg_c, joint_p)[0] - z
    if f_lo < 0.0:
        return False
    f_hi = _column(hi, seg_l, seg_w, seg_c, joint_p)[0] - z
    if f_hi > 0.0:
        return False
    # Illinois (modified regula falsi) on f(lb) = column height - z, bracketed in [x, lmax]
    lb = hi if f_hi == 0.0 else lo
    side = 0
    for _ in range(200 if f_hi != 0.0 and f_lo != 0.0 else 0):
        lb = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not lo < lb < hi:
            lb = 0.5 * (lo + hi)
        f = _column(lb, seg_l, seg_w, seg_c, joint_p)[0] - z
        if f == 0.0 or hi - lo <= 1e-14 * lmax:
            break
        if f > 0.0:  # column too high: more on the seabed
            lo = lb
            f_lo = f
            if side == 1:
                f_hi *= 0.5
            side = 1
        else:
            hi = lb
            f_hi = f
            if side == -1:
                f_lo *= 0.5
            side = -1
        if abs(f) <= 1e-14 * (lmax + abs(z)):
            break
    zc, vf, z_min, k_td = _column(lb, seg_l, seg_w, seg_c, joint_p)
    ltot = seg_l.sum()
    d = 1e-7 * ltot
    dz_dlb = (_column(min(lb + d, lmax), seg_l, seg_w, seg_c, joint_p)[0]
              - _column(max(lb - d, 0.0), seg_l, seg_w, seg_c, joint_p)[0]) \
        / (min(lb + d, lmax) - max(lb - d, 0.0))
    out[0] = 0.0
    out[1] = vf
    out[2] = 0.0
    out[3] = 0.0
    out[4] = lb
    out[5] = SLACK_PILED if z > 0.0 else ON_SEABED
    out[6] = OK if z_min >= -1e-9 * ltot else OFF_SEABED_MODEL
    # no horizontal restoring force; lifting the fairlead lifts material off the touchdown
    out[7] = 0.0
    out[8] = 0.0
    out[9] = 0.0
    out[10] = -seg_w[k_td] / dz_dlb if dz_dlb < 0.0 else math.inf
    v = 0.0
    start = 0.0
    for k in range(seg_l.shape[0] - 1):
        end = start + seg_l[k]
        if end > lb:
            v += seg_w[k] * (end - max(start, lb))
            joint_h[k] = 0.0
            joint_v[k] = v
            v += joint_p[k]
        else:
            joint_h[k] = 0.0
            joint_v[k] = 0.0
        start = end
    return True


@kernel()
def _guess(x, z, seg_l, seg_w, seg_c, joint_p, attempt):
    ltot = 0.0
    wtot = 0.0
    wabs = 0.0
    cl = 0.0
    for k in range(seg_l.shape[0]):
        ltot += seg_l[k]
        wtot += seg_w[k] * seg_l[k]
        wabs += abs(seg_w[k]) * seg_l[k]
        cl += seg_c[k] * seg_l[k]
    for k in range(joint_p.shape[0]):
        wtot += joint_p[k]
        wabs += abs(joint_p[k])
    if wabs == 0.0:
        wabs = 1.0
    d = np.hypot(x, z)
    if ltot > d:
        # inextensible homogeneous catenary through both ends (exact for such a line):
        # sinh(phi)/phi = sqrt(L^2 - z^2)/x = 1 + q
        xe = max(x, 1e-12 * ltot)
        sq = math.sqrt((ltot - z) * (ltot + z))
        q = (ltot - d) * (ltot + d) / (xe * (sq + xe))
        phi = _phi_from_excess(q)
        weff = wtot / ltot
        if abs(wtot) < 0.05 * wabs:
            weff = wabs / ltot
        h = abs(weff) * max(x, 1e-9 * ltot) / (2.0 * phi)
        m = math.atanh(min(max(z / ltot, -0.999999), 0.999999))
        if weff > 0.0:
            vf = h * math.sinh(m + phi)
        else:
            vf = h * math.sinh(m - phi)
    else:
        strain = max(d / ltot - 1.0, 1e-6)
        t = strain * ltot / cl if cl > 0.0 else wabs
        h = t * x / d + 1e-6 * wabs
        vf = t * z / d + 0.5 * wtot
    if attempt == 1:
        h *= 10.0
    elif attempt == 2:
        h *= 0.1
    elif attempt == 3:
        h = wabs
        vf = wtot
    return max(h, 1e-12 * wabs), vf


@kernel()
def solve_one(x, z, seg_l, seg_w, seg_c, joint_p, mu, seabed, tol, joint_h, joint_v, out,
              h_warm=0.0, v_warm=0.0):
    """Solve one fairlead position, trying (h_warm, v_warm) first if h_warm > 0 (the previous
    sample's answer in a stream); results into out[0:11]:
    H, VF, H_anchor, V_anchor, grounded, regime, status, kxx, kxz, kzx, kzz
    (stiffness k.. = d(H or VF)/d(x or z) at the fairlead)."""
    n = seg_l.shape[0]
    ltot = 0.0
    wabs = 0.0
    for k in range(n):
        ltot += seg_l[k]
        wabs += abs(seg_w[k]) * seg_l[k]
    for k in range(joint_p.shape[0]):
        wabs += abs(joint_p[k])
    if wabs == 0.0:
        wabs = 1.0
    scale = ltot + abs(x) + abs(z)
    if seabed and slack_piled(x, z, seg_l, seg_w, seg_c, joint_p, _heavy_prefix(seg_w, joint_p),
                              joint_h, joint_v, out):
        return
    xs = max(x, 1e-9 * ltot)  # a vertical line is the limit H -> 0+
    on_bed = seabed and z <= 1e-9 * ltot
    if on_bed:
        z = 0.0
    # an all-heavy line on a seabed needs VF > 0 to lift its fairlead off the bottom
    keep_vf_positive = seabed and not on_bed and np.all(seg_w > 0.0) and np.all(joint_p >= 0.0)
    best_h = 0.0
    best_v = 0.0
    best_err = 1e300
    for attempt in range(-1 if h_warm > 0.0 else 0, 4):
        if attempt < 0:
            h, vf = h_warm, v_warm
        else:
            h, vf = _guess(xs, z, seg_l, seg_w, seg_c, joint_p, attempt)
        if on_bed:
            vf = 0.0
        converged = False
        for it in range(30 if attempt < 0 else 200):
            rx, rz, jxh, jxv, jzh, jzv, ha, va, gl, reg, valid = evaluate(
                h, vf, xs, z, seg_l, seg_w, seg_c, joint_p, mu, seabed, joint_h, joint_v)
            err = abs(rx) + abs(rz)
            if err < best_err:
                best_err = err
                best_h = h
                best_v = vf
            if err <= tol * scale:
                converged = True
                break
            if on_bed:
                # fairlead on the seabed: VF = 0, one unknown
                du = -rx / (jxh * h)
                dv = 0.0
            else:
                # Newton in (ln H, VF)
                a11 = jxh * h
                a21 = jzh * h
                det = a11 * jzv - jxv * a21
                if det == 0.0 or not math.isfinite(det):
                    break
                du = (-rx * jzv + jxv * rz) / det
                dv = (-a11 * rz + a21 * rx) / det
            lim = 2.0
            if abs(du) > lim:
                dv *= lim / abs(du)
                du = lim * math.copysign(1.0, du)
            vlim = 2.0 * (abs(vf) + h + wabs)
            if abs(dv) > vlim:
                du *= vlim / abs(dv)
                dv = vlim * math.copysign(1.0, dv)
            # backtracking on the residual norm
            lam = 1.0
            accepted = False
            for _ in range(40):
                h_new = h * math.exp(lam * du)
                v_new = vf + lam * dv
                if keep_vf_positive and v_new <= 0.0:
                    # a heavy top segment with VF <= 0 would lie flat: no height gained
                    v_new = 0.5 * vf if vf > 0.0 else 1e-3 * wabs
                r2 = evaluate(h_new, v_new, xs, z, seg_l, seg_w, seg_c, joint_p, mu, seabed,
                              joint_h, joint_v)
                if abs(r2[0]) + abs(r2[1]) < err:
                    accepted = True
                    break
                lam *= 0.5
            h = h_new
            vf = v_new
            if not accepted and lam * (abs(du) + abs(dv) / (abs(vf) + h + wabs)) < 1e-15:
                break
        if converged:
            break
    else:
        h = best_h
        vf = best_v
    rx, rz, jxh, jxv, jzh, jzv, ha, va, gl, reg, valid = evaluate(
        h, vf, xs, z, seg_l, seg_w, seg_c, joint_p, mu, seabed, joint_h, joint_v)
    out[0] = h
    out[1] = vf
    out[2] = ha
    out[3] = va
    out[4] = gl
    out[5] = reg
    if abs(rx) + abs(rz) > 100.0 * tol * scale:
        out[6] = NOT_CONVERGED
    else:
        out[6] = OK if valid else OFF_SEABED_MODEL
    if on_bed:
        # lifting a fairlead that lies on the seabed: V ~ sqrt(2 w H dz), unbounded slope
        out[7] = 1.0 / jxh
        out[8] = 0.0
        out[9] = 0.0
        out[10] = math.inf
        return
    det = jxh * jzv - jxv * jzh
    out[7] = jzv / det
    out[8] = -jxv / det
    out[9] = -jzh / det
    out[10] = jxh / det


@kernel()
def solve_many(xs, zs, seg_l, seg_w, seg_c, joint_p, mu, seabed, tol, out, joints_h, joints_v):
    """Solve a sequence of fairlead positions; each warm-starts from the previous answer
    (samples of a motion record are close to each other)."""
    h_prev = 0.0
    v_prev = 0.0
    for i in range(xs.shape[0]):
        solve_one(xs[i], zs[i], seg_l, seg_w, seg_c, joint_p, mu, seabed, tol,
                  joints_h[i], joints_v[i], out[i], h_prev, v_prev)
        ok = out[i, 6] == OK and out[i, 0] > 0.0
        h_prev = out[i, 0] if ok else 0.0
        v_prev = out[i, 1] if ok else 0.0
