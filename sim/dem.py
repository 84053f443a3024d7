"""The twin's compiled soft-sphere DEM step loop (numba): pure functions of arrays.

Model (the standard linear spring-dashpot DEM of Cundall & Strack 1979, in 2D):

* **Normal**: ``F_n = max(0, k_n delta + c_n d(delta)/dt)`` with overlap ``delta``
  (m), linear stiffness ``k_n`` (N/m) and the viscous coefficient that gives the
  restitution ``e`` for the pair's effective mass ``m*``: ``c_n = 2 zeta sqrt(m* k_n)``
  with ``zeta = damping_ratio(e)``, exact for a contact that ends when the force
  reaches zero (no pull; Schwager & Poeschel 2008).
* **Tangential**: a spring ``k_t = 2/7 k_n`` on the accumulated tangential displacement
  ``xi`` (a scalar in 2D) plus a dashpot ``c_t = 2/7 c_n`` (the same frequency and
  damping ratio as the normal direction for balls, ``I = 2/5 m r^2``), capped by
  Coulomb ``|F_t| <= mu F_n``; at the cap the spring is reset to ``mu F_n / k_t``.
* **Rolling friction**: the "constant directional torque" model (Ai, Chen, Rotter &
  Ooi, Powder Technol. 206, 2011, type A; LIGGGHTS ``rolling_friction cdt``, EDEM's RVD
  rolling friction): a torque
  ``mu_r r_eff F_n`` with ``r_eff = r_i r_j / (r_i + r_j)`` (``r_i`` at the wall)
  against the relative rotation ``omega_i - omega_j`` (the drum's rate at the wall),
  applied as an angular impulse after the velocity update, contact by contact in a
  fixed order, each capped so that it cannot reverse the relative rotation. No contact,
  no torque.
* **Wall**: the drum is the exact circle of radius ``R``, a smooth rigid boundary
  turning at the drum's rate: overlap ``|x| + r - R``, the same contact law with the
  disk's own mass as ``m*`` and the wall's sliding friction.
* **Stiffness**: every contact lasts the same time (``contact_tables``): ``k_n`` of a pair
  (or of a disk at the wall) in proportion to its effective mass.
* **End plates** (the drum's depth ``W``; Taberlet et al. 2003's side-wall friction of a
  quasi-2D flow): a force ``mu_end r_i sum(F_n) / W`` (``sum(F_n)``: the normal forces on
  disk i this step, N) against its velocity relative to the plates, which turn with the drum;
  capped so that it cannot reverse that velocity within a step.
* **Drum torque**: the moment about the axis of every force the bed puts on the drum, summed per
  step into ``acc[ACC_TORQUE]`` (N m; counter-clockwise positive, ``ACC_TORQUE_STEPS`` steps): the
  wall's tangential forces at its radius ``R`` (the normal forces are radial: no moment), the
  angular impulses of rolling friction at the wall over the step, and the reaction of the end
  plates' friction at each disk's centre (that share sampled every ``END_TORQUE_EVERY`` steps, its
  mean over the samples counted for every step of the call: its own loop costs a tenth of a step).
  (What the drive must supply to keep the drum turning at a steady speed is minus this.)
* **Integration**: symplectic Euler (``v += F/m dt`` then ``x += v dt``) at a fixed step.
* **Neighbours**: a Verlet list (pairs ``j > i`` within ``r_i + r_j + skin``, sorted
  by ``j``, in compressed rows) rebuilt whenever a disk has moved more than half the skin since
  the last build: O(N), the disks counted into cells (a counting sort) and each pair found once
  from a half stencil of cells. The skin of each build is chosen from the fastest disk
  (``list_skin``: wide enough to last about ``SKIN_STEPS`` steps, between the caller's
  ``P_SKIN`` and ``SKIN_MAX_R`` small radii), so fast-flowing beds rebuild less often.
  Contacts are visited in (i, j) order and forces are summed in that order, so the result
  depends neither on when the list was rebuilt nor on its skin: a restored state
  continues bit-identically.

All lengths in m, times in s, forces in N. ``run`` advances many steps in one call.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from sim.dem_neighbours import list_skin, rebuild_list

__all__ = [
    "ACC_AIRBORNE", "ACC_CONTACTS", "ACC_N", "ACC_OVERLAP_MAX", "ACC_TORQUE", "ACC_TORQUE_STEPS", "ACC_WALL_MAX",
    "DS_ANGLE", "DS_RPM", "DS_TARGET", "END_TORQUE_EVERY",
    "P_ACCEL", "P_DAMP", "P_DT", "P_END", "P_G", "P_MU", "P_MU_R", "P_MU_W", "P_N", "P_R", "P_RMIN",
    "P_SKIN", "run",
]

# slots of the float parameter vector ``prm``
P_DT = 0  # step, s
P_MU = 1  # disk-disk sliding friction
P_MU_W = 2  # disk-wall sliding friction
P_MU_R = 3  # rolling friction coefficient
P_G = 4  # gravity, m/s^2 (along -y)
P_R = 5  # drum radius, m
P_SKIN = 6  # smallest Verlet skin, m (``list_skin``)
P_DAMP = 7  # global velocity damping rate, 1/s (settling only; 0 in a run)
P_ACCEL = 8  # drum acceleration limit, rpm/s
P_RMIN = 9  # small radius, m (unit of the overlap statistics)
P_END = 10  # end-plate friction over the drum's depth, mu_end / depth, 1/m (0: no end plates)
P_N = 11

# slots of the drum state ``ds``
DS_RPM = 0  # drum speed now, rpm
DS_TARGET = 1  # setpoint, rpm
DS_ANGLE = 2  # drum angle, rad

# slots of the statistics ``acc``
ACC_OVERLAP_MAX = 0  # largest disk-disk overlap, small radii
ACC_WALL_MAX = 1  # deepest wall penetration, m
ACC_CONTACTS = 2  # disk-disk contacts counted (summed over steps)
ACC_AIRBORNE = 3  # fraction of disks without any contact in the last step
ACC_TORQUE = 4  # torque of the bed on the drum about its axis, N m (counter-clockwise +), summed over steps
ACC_TORQUE_STEPS = 5  # steps summed into ACC_TORQUE
ACC_N = 6

_RPM_TO_RAD_S = 2.0 * math.pi / 60.0

END_TORQUE_EVERY = 16  # steps between samples of the end plates' share of the drum torque


_CT_SCALE = 2.0 / 7.0  # tangential dashpot / normal dashpot


@njit(inline="always")
def _contact_law(delta, vn, vt, xi_old, cn, mu, kn, kt, inv_kt, dt):
    """One contact's forces: normal ``max(0, k_n delta + c_n vn)`` (N; ``delta`` overlap in m,
    ``vn`` its rate in m/s) and the Cundall-Strack tangential force (N) from the spring
    ``xi_old + vt dt`` (m; ``vt`` the tangential slip velocity, m/s) and its dashpot, capped at
    ``mu`` times the normal force (the spring then reset to the cap). Returns ``(fn, ft, xi)``."""
    fn = max(kn * delta + cn * vn, 0.0)
    xi = xi_old + vt * dt
    ft = -kt * xi - _CT_SCALE * cn * vt
    lim = mu * fn
    ftc = min(max(ft, -lim), lim)
    if ftc != ft:
        xi = -ftc * inv_kt
    return fn, ftc, xi


@njit(cache=True, error_model="numpy", fastmath={"contract", "arcp", "nsz", "afn"})
def run(
    n_steps,  # int: steps to run
    prm,  # (P_N,) float parameters (P_* slots)
    ds,  # (3,) drum state (DS_* slots), updated
    pos,  # (n, 2) centres, m, updated
    vel,  # (n, 2) velocities, m/s, updated
    ang,  # (n,) angles, rad, updated
    omg,  # (n,) angular velocities, rad/s, updated
    rad,  # (n,) radii, m
    cls,  # (n,) class index
    inv_m,  # (n,) 1 / mass, 1/kg
    inv_i,  # (n,) 1 / moment of inertia
    c_pair,  # (n_cls, n_cls, 6) per class pair: normal damping (N s/m), r_eff (m), 1 / (1/I_i + 1/I_j),
    #          normal and tangential stiffness (N/m), 1 / tangential stiffness (m/N)
    c_wall,  # (n_cls, 4) per class at the wall: normal damping (N s/m), k_n, k_t (N/m), 1 / k_t (m/N)
    nb_start,  # (n + 1,) row starts of the neighbour list, updated
    nb_j,  # (cap,) neighbour list (compressed rows: j > i, sorted), updated
    nb_xi,  # (cap,) tangential spring of each listed pair, m, updated
    wall_xi,  # (n,) tangential spring at the wall, m, updated
    ref,  # (n, 2) centres at the last list build, updated
    rebuild,  # bool: build the list before the first step
    hist,  # overlap histogram (bins of 2 / (hist.size - 1) small radii, last = overflow), updated
    acc,  # (ACC_N,) statistics (ACC_* slots), updated
    ncont,  # (n,) contacts of each disk in the last step, updated
):
    """Run ``n_steps`` fixed steps; returns the steps run (fewer only if the neighbour list overflowed).

    Long on purpose (a numba kernel): one compiled step loop keeps each disk's sums in registers, and
    splitting it changes how LLVM contracts its updates (runs no longer bit-identical; ``_end_plate_torque``)."""
    n = pos.shape[0]
    cap = nb_j.size
    dt = prm[P_DT]
    mu = prm[P_MU]
    mu_w = prm[P_MU_W]
    mu_r = prm[P_MU_R]
    g = prm[P_G]
    r_drum = prm[P_R]
    skin_min = prm[P_SKIN]
    damp = math.exp(-prm[P_DAMP] * dt)
    accel = prm[P_ACCEL] * dt
    r_min = prm[P_RMIN]
    end_w = prm[P_END] * dt
    nbins = hist.size - 1
    bin_scale = nbins / (2.0 * r_min)
    ov_max = acc[ACC_OVERLAP_MAX] * r_min
    wall_max = acc[ACC_WALL_MAX]
    n_contacts = 0
    # the list's skin is known only for builds in this call: an older list is checked against the
    # smallest skin (it was built at least that wide, so no contact is missed)
    half_skin2 = 0.25 * skin_min * skin_min
    mu_r_dt = mu_r * dt
    r_max = 0.0
    for i in range(n):
        r_max = max(r_max, rad[i])
    # the overlap histogram in four lanes (contact k in lane k % 4): consecutive contacts, mostly in
    # the same bin, then do not wait on each other's increments; summed into ``hist`` at the end
    lanes = np.zeros((4, hist.size), dtype=hist.dtype)
    frc = np.zeros((n, 4))  # per disk: force x, y (N), torque (N m), sum of normal forces (N, end plates)
    weight = np.empty(n)
    mass = np.empty(n)
    for i in range(n):
        mass[i] = 1.0 / inv_m[i]
        weight[i] = -g * mass[i]
    inv_dt = 1.0 / dt
    tq_sum = 0.0  # torque of the bed on the drum (N m, counter-clockwise +), summed over this call's steps
    end_sum = 0.0  # the end plates' share at the sampled steps (N m), and their count
    end_cnt = 0
    # this step's contacts in visiting order (i, then the wall, then i's partners j): for rolling friction
    roll_start = np.zeros(n + 1, dtype=np.int64)
    roll_j = np.empty(cap + n, dtype=np.int64)  # partner, -1 = the wall
    roll_imp = np.empty(cap + n)  # rolling friction angular impulse bound mu_r r_eff F_n dt
    roll_cap = np.empty(cap + n)  # impulse that stops the relative rotation, per rad/s
    new_j = np.empty(cap, dtype=np.int64)  # scratch of the list builds
    new_xi = np.empty(cap)
    # the disks' hot state in one row each (one or two cache lines per partner in the contact loop):
    # x, y (m), vx, vy (m/s), omega (rad/s), radius (m), class, 1 / moment of inertia; written back at the end
    hot = np.empty((n, 8))
    for i in range(n):
        hot[i, 0] = pos[i, 0]
        hot[i, 1] = pos[i, 1]
        hot[i, 2] = vel[i, 0]
        hot[i, 3] = vel[i, 1]
        hot[i, 4] = omg[i]
        hot[i, 5] = rad[i]
        hot[i, 6] = cls[i]
        hot[i, 7] = inv_i[i]
    for i in range(n):  # the forces start at the weight (and are reset so after each step)
        frc[i, 1] = weight[i]
    far = 0.0
    for i in range(n):
        dx = hot[i, 0] - ref[i, 0]
        dy = hot[i, 1] - ref[i, 1]
        far = max(far, dx * dx + dy * dy)
    if rebuild:  # (on the hot rows, as in the step loop: one compiled form of the list build)
        far = 0.0
        skin = list_skin(hot[:, 2:4], dt, skin_min, r_min)
        if not rebuild_list(hot, rad, nb_start, nb_j, nb_xi, new_j, new_xi, ref, skin, r_drum, r_max):
            return 0
        half_skin2 = 0.25 * skin * skin
    for step in range(n_steps):
        # the drum follows its setpoint at the acceleration limit
        if ds[DS_RPM] != ds[DS_TARGET]:
            diff = ds[DS_TARGET] - ds[DS_RPM]
            ds[DS_RPM] = ds[DS_TARGET] if abs(diff) <= accel else ds[DS_RPM] + math.copysign(accel, diff)
        w_drum = ds[DS_RPM] * _RPM_TO_RAD_S
        v_wall = w_drum * r_drum
        # neighbour list still valid? (``far``: the largest squared move since the last build)
        if far > half_skin2:
            skin = list_skin(hot[:, 2:4], dt, skin_min, r_min)
            if not rebuild_list(hot, rad, nb_start, nb_j, nb_xi, new_j, new_xi, ref, skin, r_drum, r_max):
                tq_sum += step * end_sum / max(end_cnt, 1)
                _store(acc, ov_max / r_min, wall_max, n_contacts, ncont, hist, lanes, tq_sum, step)
                _unpack(hot, pos, vel, omg)
                return step
            half_skin2 = 0.25 * skin * skin
        last = step == n_steps - 1  # contacts per disk are counted in the last step only
        if last:
            for i in range(n):
                ncont[i] = 0
        m = 0
        for i in range(n):
            roll_start[i] = m
            xi0 = hot[i, 0]
            yi0 = hot[i, 1]
            vxi = hot[i, 2]
            vyi = hot[i, 3]
            wi = hot[i, 4]
            ri = hot[i, 5]
            ci = int(hot[i, 6])
            # the drum wall: the exact circle, turning at w_drum
            d2 = xi0 * xi0 + yi0 * yi0
            lim_r = r_drum - ri
            if d2 > lim_r * lim_r and d2 > 0.0:
                d = math.sqrt(d2)
                nx = xi0 / d
                ny = yi0 / d
                delta = d - lim_r
                vt = -vxi * ny + vyi * nx + wi * ri - v_wall
                fn, ft, wall_xi[i] = _contact_law(delta, vxi * nx + vyi * ny, vt, wall_xi[i], c_wall[ci, 0],
                                                  mu_w, c_wall[ci, 1], c_wall[ci, 2], c_wall[ci, 3], dt)
                frc[i, 0] += -fn * nx - ft * ny
                frc[i, 1] += -fn * ny + ft * nx
                frc[i, 2] += ri * ft
                frc[i, 3] += fn
                tq_sum -= r_drum * ft  # the reaction at the wall, lever R (the normal force is radial)
                if last:
                    ncont[i] += 1
                if delta > wall_max:
                    wall_max = delta
                roll_j[m] = -1
                roll_imp[m] = mu_r * ri * fn * dt
                m += 1
            else:
                wall_xi[i] = 0.0
            # disk-disk contacts (j > i: the sums of disk i stay in registers)
            fxi = 0.0
            fyi = 0.0
            tqi = 0.0
            sfi = 0.0
            nci = 0
            for k in range(nb_start[i], nb_start[i + 1]):
                j = nb_j[k]
                dx = hot[j, 0] - xi0
                dy = hot[j, 1] - yi0
                rj = hot[j, 5]
                rs = ri + rj
                d2 = dx * dx + dy * dy
                if d2 >= rs * rs:
                    nb_xi[k] = 0.0
                    continue
                d = math.sqrt(d2)
                inv_d = 1.0 / d
                nx = dx * inv_d
                ny = dy * inv_d
                dvx = vxi - hot[j, 2]
                dvy = vyi - hot[j, 3]
                delta = rs - d
                cj = int(hot[j, 6])
                vt = -dvx * ny + dvy * nx + wi * ri + hot[j, 4] * rj
                cp = c_pair[ci, cj]
                fn, ft, nb_xi[k] = _contact_law(delta, dvx * nx + dvy * ny, vt, nb_xi[k], cp[0],
                                                mu, cp[3], cp[4], cp[5], dt)
                fxc = -fn * nx - ft * ny
                fyc = -fn * ny + ft * nx
                fxi += fxc
                fyi += fyc
                tqi += ri * ft
                sfi += fn
                nci += 1
                frc[j, 0] -= fxc
                frc[j, 1] -= fyc
                frc[j, 2] += rj * ft
                frc[j, 3] += fn
                if last:
                    ncont[j] += 1
                if delta > ov_max:
                    ov_max = delta
                lanes[n_contacts & 3, min(int(delta * bin_scale), nbins)] += 1
                n_contacts += 1
                roll_j[m] = j
                roll_imp[m] = mu_r_dt * cp[1] * fn
                roll_cap[m] = cp[2]
                m += 1
            frc[i, 0] += fxi
            frc[i, 1] += fyi
            frc[i, 2] += tqi
            frc[i, 3] += sfi
            if last:
                ncont[i] += nci
        roll_start[n] = m
        # angular velocities
        for i in range(n):
            hot[i, 4] = (hot[i, 4] + frc[i, 2] * hot[i, 7] * dt) * damp
        # rolling friction: angular impulses contact by contact, each capped so that it
        # cannot reverse the relative rotation (disk i's spin is final after its row: its
        # angle moves on there)
        if mu_r > 0.0:
            for i in range(n):
                wi = hot[i, 4]
                ii = hot[i, 7]
                for c in range(roll_start[i], roll_start[i + 1]):
                    j = roll_j[c]
                    jr = roll_imp[c]
                    if j < 0:
                        w_rel = wi - w_drum
                        dw = math.copysign(min(jr * ii, abs(w_rel)), w_rel)
                        wi -= dw
                        tq_sum += dw / ii * inv_dt  # the drum takes the opposite angular impulse
                    else:
                        w_rel = wi - hot[j, 4]
                        sj = math.copysign(min(jr, abs(w_rel) * roll_cap[c]), w_rel)
                        wi -= sj * ii
                        hot[j, 4] += sj * hot[j, 7]
                hot[i, 4] = wi
                ang[i] += wi * dt
        else:
            for i in range(n):
                ang[i] += hot[i, 4] * dt
        if end_w > 0.0 and step % END_TORQUE_EVERY == 0:  # sampled (at 1/16 of the cost)
            end_sum += _end_plate_torque(hot, frc, inv_m, mass, w_drum, end_w, dt)
            end_cnt += 1
        # velocities and positions; the largest move since the list was built; forces reset
        far = 0.0
        for i in range(n):
            vx = hot[i, 2] + frc[i, 0] * inv_m[i] * dt
            vy = hot[i, 3] + frc[i, 1] * inv_m[i] * dt
            if end_w > 0.0:
                # end-plate friction: against the velocity relative to the end plates (turning with the
                # drum), mu_end r_i sum(F_n) / depth, capped so it cannot reverse that velocity in a step
                ux = vx + w_drum * hot[i, 1]
                uy = vy - w_drum * hot[i, 0]
                u = math.sqrt(ux * ux + uy * uy)
                dv = end_w * hot[i, 5] * frc[i, 3] * inv_m[i]
                if u > 0.0:
                    s = min(dv, u) / u
                    vx -= s * ux
                    vy -= s * uy
            vx *= damp
            vy *= damp
            hot[i, 2] = vx
            hot[i, 3] = vy
            px = hot[i, 0] + vx * dt
            py = hot[i, 1] + vy * dt
            hot[i, 0] = px
            hot[i, 1] = py
            dx = px - ref[i, 0]
            dy = py - ref[i, 1]
            far = max(far, dx * dx + dy * dy)
            frc[i, 0] = 0.0
            frc[i, 1] = weight[i]
            frc[i, 2] = 0.0
            frc[i, 3] = 0.0
        ds[DS_ANGLE] += w_drum * dt
    tq_sum += n_steps * end_sum / max(end_cnt, 1)  # the sampled mean over every step of the call
    _store(acc, ov_max / r_min, wall_max, n_contacts, ncont, hist, lanes, tq_sum, n_steps)
    _unpack(hot, pos, vel, omg)
    return n_steps


@njit(cache=True, error_model="numpy", fastmath={"contract", "arcp", "nsz", "afn"})
def _end_plate_torque(hot, frc, inv_m, mass, w_drum, end_w, dt):
    """Moment about the axis (N m, counter-clockwise +) of the end plates' reaction to this step's end-plate
    friction: the plates take the opposite of each disk's impulse ``m dv`` at its centre.

    This repeats ``run``'s end-plate velocity update on purpose: any use of its values inside ``run``
    (inline or not) changes how LLVM contracts that update, and the runs would then no longer be
    bit-identical to those of the model without the torque (measured: one 3 s calibration slope moved
    by 2 deg, which is the bed's chaos, not physics)."""
    tq = 0.0
    for i in range(hot.shape[0]):
        vx = hot[i, 2] + frc[i, 0] * inv_m[i] * dt
        vy = hot[i, 3] + frc[i, 1] * inv_m[i] * dt
        ux = vx + w_drum * hot[i, 1]
        uy = vy - w_drum * hot[i, 0]
        u = math.sqrt(ux * ux + uy * uy)
        dv = end_w * hot[i, 5] * frc[i, 3] * inv_m[i]
        if u > 0.0:
            s = min(dv, u) / u
            tq += mass[i] * s * (hot[i, 0] * uy - hot[i, 1] * ux)
    return tq / dt


@njit(cache=True)
def _unpack(hot, pos, vel, omg):
    """Write the hot rows' positions, velocities and spins back to the state arrays."""
    for i in range(pos.shape[0]):
        pos[i, 0] = hot[i, 0]
        pos[i, 1] = hot[i, 1]
        vel[i, 0] = hot[i, 2]
        vel[i, 1] = hot[i, 3]
        omg[i] = hot[i, 4]


@njit(cache=True)
def _store(acc, ov_max_r, wall_max, n_contacts, ncont, hist, lanes, tq_sum, steps):
    """Write a run's statistics into ``acc`` (its drum torque summed over ``steps`` steps: ``tq_sum``,
    N m) and its overlap histogram lanes into ``hist``."""
    for b in range(hist.size):
        hist[b] += lanes[0, b] + lanes[1, b] + lanes[2, b] + lanes[3, b]
    acc[ACC_OVERLAP_MAX] = ov_max_r
    acc[ACC_WALL_MAX] = wall_max
    acc[ACC_CONTACTS] += n_contacts
    acc[ACC_TORQUE] += tq_sum
    acc[ACC_TORQUE_STEPS] += steps
    n_free = 0
    for i in range(ncont.size):
        if ncont[i] == 0:
            n_free += 1
    acc[ACC_AIRBORNE] = n_free / max(1, ncont.size)
