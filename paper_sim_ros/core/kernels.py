"""numba kernels over flat arrays: spring forces and Jacobians, the Jacobi iteration of
Eq. 6, stretch projection, contact, the compression probes impose (damage, Eq. 7).
Inputs first, outputs last; no Python objects.

Springs scatter into their two vertices, so every loop over springs runs serially (a
``prange`` there would race); the per-vertex loops are independent.
"""
from __future__ import annotations

import numpy as np
from numba import njit

EPSILON_LENGTH = 1e-12


@njit(cache=True)
def spring_system(positions, velocities, spring_vertices, rest_length, stiffness, damping, h,
                  force, diagonal, coupling, rhs_jv):
    """Forces and the implicit-system pieces of every spring (Eq. 2–3, Baraff–Witkin blocks).

    For a spring of unit direction d, length l, rest length l0:
      S = k [ max(0, 1 - l0/l) (I - d dᵀ) + d dᵀ ]   (= -∂f_i/∂x_i, positive semi-definite)
      C = c d dᵀ                                       (= -∂f_i/∂v_i)
    The transverse term is clamped at zero for a compressed spring (l < l0), where it is
    negative and would make W = M - h ∂f/∂v - h² ∂f/∂x indefinite; this is the usual
    Baraff–Witkin remedy and only drops a destabilising term.
    Adds to ``force`` (V,3); adds B = hC + h²S to ``diagonal`` (V,3,3) of both ends; writes
    B, packed symmetric (xx, yy, zz, xy, xz, yz), to ``coupling`` (S,6); adds the h² J v term
    of Eq. 3's right-hand side to ``rhs_jv`` (V,3).
    """
    h2 = h * h
    for s in range(spring_vertices.shape[0]):
        i = spring_vertices[s, 0]
        j = spring_vertices[s, 1]
        dx = positions[j, 0] - positions[i, 0]
        dy = positions[j, 1] - positions[i, 1]
        dz = positions[j, 2] - positions[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length < EPSILON_LENGTH:
            continue
        ux = dx / length
        uy = dy / length
        uz = dz / length
        k = stiffness[s]
        c = damping[s]
        dvx = velocities[j, 0] - velocities[i, 0]
        dvy = velocities[j, 1] - velocities[i, 1]
        dvz = velocities[j, 2] - velocities[i, 2]
        # Hooke plus axial damping, acting on i towards j
        magnitude = k * (length - rest_length[s]) + c * (dvx * ux + dvy * uy + dvz * uz)
        force[i, 0] += magnitude * ux
        force[i, 1] += magnitude * uy
        force[i, 2] += magnitude * uz
        force[j, 0] -= magnitude * ux
        force[j, 1] -= magnitude * uy
        force[j, 2] -= magnitude * uz
        transverse = k * max(0.0, 1.0 - rest_length[s] / length)
        axial = k - transverse
        # S = transverse I + axial d dᵀ
        sxx = transverse + axial * ux * ux
        syy = transverse + axial * uy * uy
        szz = transverse + axial * uz * uz
        sxy = axial * ux * uy
        sxz = axial * ux * uz
        syz = axial * uy * uz
        # h² S (v_j - v_i) on i, the opposite on j (Eq. 3's h² J v)
        jx = h2 * (sxx * dvx + sxy * dvy + sxz * dvz)
        jy = h2 * (sxy * dvx + syy * dvy + syz * dvz)
        jz = h2 * (sxz * dvx + syz * dvy + szz * dvz)
        rhs_jv[i, 0] += jx
        rhs_jv[i, 1] += jy
        rhs_jv[i, 2] += jz
        rhs_jv[j, 0] -= jx
        rhs_jv[j, 1] -= jy
        rhs_jv[j, 2] -= jz
        hc = h * c
        bxx = h2 * sxx + hc * ux * ux
        byy = h2 * syy + hc * uy * uy
        bzz = h2 * szz + hc * uz * uz
        bxy = h2 * sxy + hc * ux * uy
        bxz = h2 * sxz + hc * ux * uz
        byz = h2 * syz + hc * uy * uz
        coupling[s, 0] = bxx
        coupling[s, 1] = byy
        coupling[s, 2] = bzz
        coupling[s, 3] = bxy
        coupling[s, 4] = bxz
        coupling[s, 5] = byz
        for v in (i, j):
            diagonal[v, 0, 0] += bxx
            diagonal[v, 1, 1] += byy
            diagonal[v, 2, 2] += bzz
            diagonal[v, 0, 1] += bxy
            diagonal[v, 1, 0] += bxy
            diagonal[v, 0, 2] += bxz
            diagonal[v, 2, 0] += bxz
            diagonal[v, 1, 2] += byz
            diagonal[v, 2, 1] += byz


@njit(cache=True)
def invert_blocks(blocks, inverse):
    """Invert every symmetric positive-definite 3×3 block (the W_ii of Eq. 5)."""
    for v in range(blocks.shape[0]):
        a = blocks[v]
        c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
        c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
        c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
        det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
        inv_det = 1.0 / det
        inverse[v, 0, 0] = c00 * inv_det
        inverse[v, 1, 0] = c01 * inv_det
        inverse[v, 2, 0] = c02 * inv_det
        inverse[v, 0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) * inv_det
        inverse[v, 1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) * inv_det
        inverse[v, 2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) * inv_det
        inverse[v, 0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) * inv_det
        inverse[v, 1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) * inv_det
        inverse[v, 2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) * inv_det


@njit(cache=True)
def jacobi_iterate(diagonal_inverse, coupling, spring_vertices, rhs, pinned, iterations,
                   delta_v, neighbour_sum):
    """Eq. 6: Δv_i ← W_ii⁻¹ (h f̃_i + h² Σ_j J_ij Δv_j), ``iterations`` times, from the
    starting guess already in ``delta_v``. Pinned vertices are filtered to Δv = 0.
    ``neighbour_sum`` (V,3) is scratch."""
    vertex_count = rhs.shape[0]
    for _ in range(iterations):
        neighbour_sum[:, :] = 0.0
        for s in range(spring_vertices.shape[0]):
            i = spring_vertices[s, 0]
            j = spring_vertices[s, 1]
            bxx = coupling[s, 0]
            byy = coupling[s, 1]
            bzz = coupling[s, 2]
            bxy = coupling[s, 3]
            bxz = coupling[s, 4]
            byz = coupling[s, 5]
            # W_ij = -B, so -W_ij Δv_j = B Δv_j
            neighbour_sum[i, 0] += bxx * delta_v[j, 0] + bxy * delta_v[j, 1] + bxz * delta_v[j, 2]
            neighbour_sum[i, 1] += bxy * delta_v[j, 0] + byy * delta_v[j, 1] + byz * delta_v[j, 2]
            neighbour_sum[i, 2] += bxz * delta_v[j, 0] + byz * delta_v[j, 1] + bzz * delta_v[j, 2]
            neighbour_sum[j, 0] += bxx * delta_v[i, 0] + bxy * delta_v[i, 1] + bxz * delta_v[i, 2]
            neighbour_sum[j, 1] += bxy * delta_v[i, 0] + byy * delta_v[i, 1] + byz * delta_v[i, 2]
            neighbour_sum[j, 2] += bxz * delta_v[i, 0] + byz * delta_v[i, 1] + bzz * delta_v[i, 2]
        for v in range(vertex_count):
            if pinned[v]:
                delta_v[v, 0] = 0.0
                delta_v[v, 1] = 0.0
                delta_v[v, 2] = 0.0
                continue
            bx = rhs[v, 0] + neighbour_sum[v, 0]
            by = rhs[v, 1] + neighbour_sum[v, 1]
            bz = rhs[v, 2] + neighbour_sum[v, 2]
            w = diagonal_inverse[v]
            delta_v[v, 0] = w[0, 0] * bx + w[0, 1] * by + w[0, 2] * bz
            delta_v[v, 1] = w[1, 0] * bx + w[1, 1] * by + w[1, 2] * bz
            delta_v[v, 2] = w[2, 0] * bx + w[2, 1] * by + w[2, 2] * bz


SPRING_BLOCK = 64
"""Springs a block of the strain limiting's sweeps (``project_springs``) holds: a sweep
passes over a block only where a vertex of its springs moved since it last did."""


@njit(cache=True)
def spring_blocks(spring_vertices, vertex_count):
    """For each vertex, the blocks of SPRING_BLOCK consecutive springs that hold a spring
    of it, as (pointer, blocks) in CSR form: what a move of that vertex makes dirty."""
    count = spring_vertices.shape[0]
    incident = np.zeros(vertex_count + 1, dtype=np.int64)
    for s in range(count):
        incident[spring_vertices[s, 0] + 1] += 1
        incident[spring_vertices[s, 1] + 1] += 1
    for v in range(vertex_count):
        incident[v + 1] += incident[v]
    fill = incident[:-1].copy()
    block_of = np.empty(incident[-1], dtype=np.int64)
    for s in range(count):  # by spring: each vertex's blocks come out in order
        for end in range(2):
            v = spring_vertices[s, end]
            block_of[fill[v]] = s // SPRING_BLOCK
            fill[v] += 1
    pointer = np.zeros(vertex_count + 1, dtype=np.int64)
    blocks = np.empty(incident[-1], dtype=np.int64)
    used = 0
    for v in range(vertex_count):
        last = -1
        for k in range(incident[v], incident[v + 1]):
            if block_of[k] != last:
                last = block_of[k]
                blocks[used] = last
                used += 1
        pointer[v + 1] = used
    return pointer, blocks[:used].copy()


@njit(cache=True)
def project_springs(positions, inverse_mass, spring_vertices, rest_length, shortest, longest,
                    reverse, dirty, block_pointer, blocks):
    """One Gauss–Seidel sweep of strain limiting (Provot): a spring longer than
    ``longest`` × l0 or shorter than ``shortest`` × l0 is moved back to that bound, the
    correction shared by inverse mass. ``reverse`` sweeps from the last spring, so that
    alternating sweeps carry corrections both ways across the sheet. Returns how many
    springs it moved (none: the sweep left every position as it was).
    Only the ``dirty`` blocks of SPRING_BLOCK springs are swept (``spring_blocks``: a
    spring moved marks every block of its two vertices, itself included). A clean block's
    springs were all within the band when it was last swept and none of their vertices
    has moved since, so skipping it changes nothing: the sweep is the full sweep's."""
    count = spring_vertices.shape[0]
    block_count = (count + SPRING_BLOCK - 1) // SPRING_BLOCK
    moved = 0
    for m in range(block_count):
        block = block_count - 1 - m if reverse else m
        if not dirty[block]:
            continue
        dirty[block] = False
        first = block * SPRING_BLOCK
        last = min(first + SPRING_BLOCK, count)
        for n in range(last - first):
            s = last - 1 - n if reverse else first + n
            i = spring_vertices[s, 0]
            j = spring_vertices[s, 1]
            wi = inverse_mass[i]
            wj = inverse_mass[j]
            w = wi + wj
            if w == 0.0:
                continue
            dx = positions[j, 0] - positions[i, 0]
            dy = positions[j, 1] - positions[i, 1]
            dz = positions[j, 2] - positions[i, 2]
            squared = dx * dx + dy * dy + dz * dz
            upper = longest * rest_length[s]
            lower = shortest * rest_length[s]
            # most springs are within the band: no square root for them
            if lower * lower < squared < upper * upper:
                continue
            length = np.sqrt(squared)
            if length < EPSILON_LENGTH:
                continue
            if length > upper:
                target = upper
            elif length < lower:
                target = lower
            else:
                continue
            scale = (length - target) / (length * w)
            positions[i, 0] += wi * scale * dx
            positions[i, 1] += wi * scale * dy
            positions[i, 2] += wi * scale * dz
            positions[j, 0] -= wj * scale * dx
            positions[j, 1] -= wj * scale * dy
            positions[j, 2] -= wj * scale * dz
            for k in range(block_pointer[i], block_pointer[i + 1]):
                dirty[blocks[k]] = True
            for k in range(block_pointer[j], block_pointer[j + 1]):
                dirty[blocks[k]] = True
            moved += 1
    return moved


@njit(cache=True)
def project_attachments(positions, attached_vertex, anchor_vertex, attachment_length):
    """Long-range attachments (Kim et al. 2012): a vertex may be no farther from its
    nearest pinned vertex than their distance on the flat sheet. One pass carries the
    weight of the whole sheet to the pins, which local sweeps cannot do in few passes.
    Returns how many vertices it moved."""
    moved = 0
    for a in range(attached_vertex.shape[0]):
        v = attached_vertex[a]
        p = anchor_vertex[a]
        dx = positions[v, 0] - positions[p, 0]
        dy = positions[v, 1] - positions[p, 1]
        dz = positions[v, 2] - positions[p, 2]
        distance = np.sqrt(dx * dx + dy * dy + dz * dz)
        limit = attachment_length[a]
        if distance > limit:
            scale = limit / distance
            positions[v, 0] = positions[p, 0] + dx * scale
            positions[v, 1] = positions[p, 1] + dy * scale
            positions[v, 2] = positions[p, 2] + dz * scale
            moved += 1
    return moved


@njit(cache=True)
def _push_out_of_sphere(positions, start_positions, inverse_mass, center, center_motion,
                        radius, friction, apply_friction, pad_height, touched):
    """Move vertices inside a sphere to its surface; with ``apply_friction``, cancel (static)
    or shorten (kinetic, Coulomb: by friction × depth) their tangential slip relative to
    the sphere's own motion over the step. Marks the vertices it moved in ``touched``.
    Below ``pad_height`` (the table; -inf without one) the sphere is flattened like a
    fingertip pressed on the table: a vertex on the table under it is pinched there, not
    pushed sideways out of the sphere. Returns how many vertices it moved."""
    moved = 0
    for v in range(positions.shape[0]):
        if inverse_mass[v] == 0.0:
            continue
        dx = positions[v, 0] - center[0]
        dy = positions[v, 1] - center[1]
        dz = positions[v, 2] - center[2]
        distance = np.sqrt(dx * dx + dy * dy + dz * dz)
        if distance >= radius:
            continue
        if distance < EPSILON_LENGTH:
            # dead centre: leave along +z, the sheet's rest normal
            nx, ny, nz = 0.0, 0.0, 1.0
        else:
            nx, ny, nz = dx / distance, dy / distance, dz / distance
        depth = radius - distance
        touched[v] = True
        if center[2] + radius * nz < pad_height:
            # under the flattened pad: its face, the table plane facing down, is the
            # contact; the vertex is pressed onto the table and pinched there
            depth = max(0.0, positions[v, 2] - pad_height)
            nx, ny, nz = 0.0, 0.0, -1.0
        if depth > 0.0:
            moved += 1
        positions[v, 0] += depth * nx
        positions[v, 1] += depth * ny
        positions[v, 2] += depth * nz
        if apply_friction and friction > 0.0:
            sx = positions[v, 0] - start_positions[v, 0] - center_motion[0]
            sy = positions[v, 1] - start_positions[v, 1] - center_motion[1]
            sz = positions[v, 2] - start_positions[v, 2] - center_motion[2]
            normal_slip = sx * nx + sy * ny + sz * nz
            tx = sx - normal_slip * nx
            ty = sy - normal_slip * ny
            tz = sz - normal_slip * nz
            slip = np.sqrt(tx * tx + ty * ty + tz * tz)
            if slip > 0.0:
                keep = max(0.0, 1.0 - friction * depth / slip)
                positions[v, 0] -= (1.0 - keep) * tx
                positions[v, 1] -= (1.0 - keep) * ty
                positions[v, 2] -= (1.0 - keep) * tz
                moved += 1
    return moved


@njit(cache=True)
def project_ground(positions, start_positions, inverse_mass, ground_height, friction,
                   apply_friction, support):
    """Keep vertices above the table plane z = ground_height, with Coulomb friction: a
    vertex's slip along the table is cut by friction × its normal push, which is the depth
    projected out here plus ``support`` [m], the push the table gave it inside this
    sub-step's implicit solve (see ``update_table_reaction``). Returns how many vertices
    it moved."""
    moved = 0
    for v in range(positions.shape[0]):
        if inverse_mass[v] == 0.0:
            continue
        depth = ground_height - positions[v, 2]
        if depth <= 0.0 and not (apply_friction and support[v] > 0.0):
            continue
        moved += 1
        depth = max(depth, 0.0)
        positions[v, 2] = max(positions[v, 2], ground_height)
        if apply_friction and friction > 0.0:
            tx = positions[v, 0] - start_positions[v, 0]
            ty = positions[v, 1] - start_positions[v, 1]
            slip = np.sqrt(tx * tx + ty * ty)
            if slip > 0.0:
                keep = max(0.0, 1.0 - friction * (depth + support[v]) / slip)
                positions[v, 0] = start_positions[v, 0] + keep * tx
                positions[v, 1] = start_positions[v, 1] + keep * ty
    return moved


@njit(cache=True)
def normal_air_drag(velocities, normals, mass, rate, h):
    """Quadratic air drag along each vertex's unit normal, dv_n/dt = -rate |v_n| v_n
    (rate = ½ ρ C_d / grammage [1/m]: the pressure ½ ρ C_d v_n² on a vertex's area over
    its mass), taken semi-implicitly, v_n ← v_n / (1 + h rate |v_n|): it slows the normal
    speed and never reverses it, whatever the step. Returns the kinetic energy the air
    took [J]."""
    taken = 0.0
    for v in range(velocities.shape[0]):
        normal_speed = (velocities[v, 0] * normals[v, 0] + velocities[v, 1] * normals[v, 1]
                        + velocities[v, 2] * normals[v, 2])
        kept = normal_speed / (1.0 + h * rate * abs(normal_speed))
        loss = normal_speed - kept
        velocities[v, 0] -= loss * normals[v, 0]
        velocities[v, 1] -= loss * normals[v, 1]
        velocities[v, 2] -= loss * normals[v, 2]
        taken += 0.5 * mass[v] * (normal_speed * normal_speed - kept * kept)
    return taken


@njit(cache=True)
def table_friction(velocities, support, friction, h):
    """Coulomb friction of the table on the velocities a step starts from: each vertex the
    table supports (``support`` [m], its push over the last sub-step) loses up to
    friction × support / h of its sliding speed, and stops if it had less. Taken before
    the implicit solve, the solve's springs carry the pull that drags a sheet over the
    table, as its tension does, instead of friction undoing the solve vertex by vertex."""
    for v in range(velocities.shape[0]):
        if support[v] <= 0.0:
            continue
        speed = np.sqrt(velocities[v, 0] ** 2 + velocities[v, 1] ** 2)
        if speed <= 0.0:
            continue
        keep = max(0.0, 1.0 - friction * support[v] / (h * speed))
        velocities[v, 0] *= keep
        velocities[v, 1] *= keep


@njit(cache=True)
def update_table_reaction(positions, free, mass_over_h2, ground_height, reaction):
    """One projected Uzawa step on the table's reaction in an implicit solve (the solve's
    right-hand side gains ``reaction`` [N] in z): λ_v ← max(0, λ_v + m_v/h² (ground − z_v))
    over the ``free`` vertices. Returns the largest violation of the contact conditions
    (z ≥ ground, λ ≥ 0, λ (z − ground) = 0) before the update [m]."""
    worst = 0.0
    for v in free:
        gap = positions[v, 2] - ground_height
        if gap < 0.0:
            worst = max(worst, -gap)
        elif reaction[v] > 0.0:
            worst = max(worst, min(gap, reaction[v] / mass_over_h2[v]))
        reaction[v] = max(0.0, reaction[v] - mass_over_h2[v] * gap)
    return worst


@njit(cache=True)
def project_probes(positions, start_positions, inverse_mass, probe_start, probe_end,
                   probe_radius, probe_active, friction, sweep, pad_height, touched):
    """Push vertices out of every active probe. With ``sweep`` the probe is swept from its
    start to its end centre in moves of at most a quarter radius, so that a probe faster
    than one radius per step pushes the sheet along instead of tunnelling through it;
    friction acts on the final position only. ``touched`` (V,) bool marks every vertex a
    probe moved. Returns how many pushes it made (a vertex may count once per move)."""
    moved = 0
    motion = np.empty(3)
    center = np.empty(3)
    for p in range(probe_radius.shape[0]):
        if not probe_active[p]:
            continue
        radius = probe_radius[p]
        for k in range(3):
            motion[k] = probe_end[p, k] - probe_start[p, k]
        travel = np.sqrt(motion[0] ** 2 + motion[1] ** 2 + motion[2] ** 2)
        moves = 1
        if sweep:
            moves = max(1, int(np.ceil(travel / (0.25 * radius))))
        for m in range(1, moves + 1):
            fraction = m / moves
            for k in range(3):
                center[k] = probe_start[p, k] + fraction * motion[k]
            moved += _push_out_of_sphere(positions, start_positions, inverse_mass, center,
                                         motion, radius, friction, sweep and m == moves,
                                         pad_height, touched)
    return moved


@njit(cache=True, inline='always')
def _closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Barycentric weights (wa, wb, wc) of the point of triangle abc nearest p (Ericson,
    Real-Time Collision Detection, 5.1.5)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        t = d1 / (d1 - d3)
        return 1.0 - t, t, 0.0
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6)
        return 1.0 - t, 0.0, t
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - t, t
    total = va + vb + vc
    if total <= 0.0:  # degenerate (collapsed) triangle: its first corner
        return 1.0, 0.0, 0.0
    v = vb / total
    w = vc / total
    return 1.0 - v - w, v, w


@njit(cache=True)
def project_probes_on_triangles(positions, inverse_mass, triangles, probe_start, probe_end,
                                probe_radius, small, pad_height, touched):
    """Push the triangles out of every ``small`` probe (one that fits between a triangle's
    corners, so that no vertex need touch it), swept from its start to its end centre in
    moves of at most a quarter radius: where a triangle's point nearest the centre is
    inside, its corners move along the way out by the depth, shared by their barycentric
    weights and inverse masses (a point-triangle constraint, as position-based dynamics
    does). Where the way out leaves below ``pad_height`` (the table) the probe is
    flattened, and the triangle is pinched there, not pushed. Marks the moved corners in
    ``touched``; returns how many triangles it pushed."""
    moved = 0
    centre = np.empty(3)
    for p in range(probe_radius.shape[0]):
        if not small[p]:
            continue
        radius = probe_radius[p]
        travel = 0.0
        for k in range(3):
            travel += (probe_end[p, k] - probe_start[p, k]) ** 2
        moves = max(1, int(np.ceil(np.sqrt(travel) / (0.25 * radius))))
        for m in range(1, moves + 1):
            fraction = m / moves
            for k in range(3):
                centre[k] = (1.0 - fraction) * probe_start[p, k] + fraction * probe_end[p, k]
            for t in range(triangles.shape[0]):
                a = triangles[t, 0]
                b = triangles[t, 1]
                c = triangles[t, 2]
                # cheap rejection: the sphere misses the triangle's bounding sphere
                gx = (positions[a, 0] + positions[b, 0] + positions[c, 0]) / 3.0
                gy = (positions[a, 1] + positions[b, 1] + positions[c, 1]) / 3.0
                gz = (positions[a, 2] + positions[b, 2] + positions[c, 2]) / 3.0
                bound = 0.0
                for corner in (a, b, c):
                    bound = max(bound, (positions[corner, 0] - gx) ** 2
                                + (positions[corner, 1] - gy) ** 2
                                + (positions[corner, 2] - gz) ** 2)
                gap = np.sqrt((centre[0] - gx) ** 2 + (centre[1] - gy) ** 2
                              + (centre[2] - gz) ** 2)
                if gap >= np.sqrt(bound) + radius:
                    continue
                wa, wb, wc = _closest_on_triangle(
                    centre[0], centre[1], centre[2],
                    positions[a, 0], positions[a, 1], positions[a, 2],
                    positions[b, 0], positions[b, 1], positions[b, 2],
                    positions[c, 0], positions[c, 1], positions[c, 2])
                nx = wa * positions[a, 0] + wb * positions[b, 0] + wc * positions[c, 0]
                ny = wa * positions[a, 1] + wb * positions[b, 1] + wc * positions[c, 1]
                nz = wa * positions[a, 2] + wb * positions[b, 2] + wc * positions[c, 2]
                nx -= centre[0]
                ny -= centre[1]
                nz -= centre[2]
                distance = np.sqrt(nx * nx + ny * ny + nz * nz)
                if distance >= radius or distance < EPSILON_LENGTH \
                        or centre[2] + radius * nz / distance < pad_height:
                    continue  # clear of it, or under its flattened pad (pinched there)
                weight = (wa * wa * inverse_mass[a] + wb * wb * inverse_mass[b]
                          + wc * wc * inverse_mass[c])
                if weight <= 0.0:
                    continue
                scale = (radius - distance) / (distance * weight)
                for corner, share in ((a, wa), (b, wb), (c, wc)):
                    step = scale * share * inverse_mass[corner]
                    if step != 0.0:
                        positions[corner, 0] += step * nx
                        positions[corner, 1] += step * ny
                        positions[corner, 2] += step * nz
                        touched[corner] = True
                moved += 1
    return moved


@njit(cache=True)
def grip_pinched(positions, inverse_mass, probe_center, probe_radius, pressing, ground_height,
                 grip_probe, grip_offset):
    """Grip the vertices a pressing probe pinches against the table: within its radius
    (plus a 2 % margin: they were just pushed to its surface) and at or below the table.
    A gripped vertex remembers its offset from the probe's centre."""
    for v in range(positions.shape[0]):
        if grip_probe[v] >= 0 or inverse_mass[v] == 0.0 or positions[v, 2] > ground_height:
            continue
        for p in range(probe_radius.shape[0]):
            if not pressing[p]:
                continue
            dx = positions[v, 0] - probe_center[p, 0]
            dy = positions[v, 1] - probe_center[p, 1]
            dz = positions[v, 2] - probe_center[p, 2]
            if dx * dx + dy * dy + dz * dz <= (1.02 * probe_radius[p]) ** 2:
                grip_probe[v] = p
                grip_offset[v, 0] = dx
                grip_offset[v, 1] = dy
                grip_offset[v, 2] = dz
                break


@njit(cache=True)
def stretched_behind(positions, ends, rest_length, centre, reach, direction, give, alignment):
    """Whether a spring with an end within ``reach`` [m] of ``centre`` is stretched beyond
    ``give`` (l > (1 + give) l0) behind it (its midpoint on the far side of the plane
    through ``centre`` across the unit ``direction``) and runs along ``direction`` (|cos|
    at least ``alignment``): paper pulled back from a fingertip moving that way."""
    reach_squared = reach * reach
    for s in range(ends.shape[0]):
        i = ends[s, 0]
        j = ends[s, 1]
        dx = positions[j, 0] - positions[i, 0]
        dy = positions[j, 1] - positions[i, 1]
        dz = positions[j, 2] - positions[i, 2]
        length_squared = dx * dx + dy * dy + dz * dz
        limit = (1.0 + give) * rest_length[s]
        if length_squared <= limit * limit:
            continue
        near = False
        behind = 0.0
        for end in (i, j):
            ex = positions[end, 0] - centre[0]
            ey = positions[end, 1] - centre[1]
            ez = positions[end, 2] - centre[2]
            near = near or ex * ex + ey * ey + ez * ez < reach_squared
            behind += ex * direction[0] + ey * direction[1] + ez * direction[2]
        if not near or behind >= 0.0:
            continue
        along = dx * direction[0] + dy * direction[1] + dz * direction[2]
        if abs(along) >= alignment * np.sqrt(length_squared):
            return True
    return False


@njit(cache=True)
def hold_gripped(positions, probe_center, pressing, grip_probe, grip_offset, ground_height):
    """Release the vertices of probes no longer pressing; carry the others along the table
    with their probe (at their gripped offset), pinched on it."""
    for v in range(positions.shape[0]):
        p = grip_probe[v]
        if p < 0:
            continue
        if not pressing[p]:
            grip_probe[v] = -1
            continue
        positions[v, 0] = probe_center[p, 0] + grip_offset[v, 0]
        positions[v, 1] = probe_center[p, 1] + grip_offset[v, 1]
        positions[v, 2] = ground_height


@njit(cache=True)
def beyond_rest_reach(positions, material, rest_shape, vertices, anchors, stretch):
    """(len(vertices),) bool: whether each of ``vertices`` is farther from any of
    ``anchors`` than ``stretch`` × the distance the paper between them reaches at rest (the
    larger of their material and rest-shape distances; paper does not stretch, so no path
    through it is longer than that from the anchor)."""
    beyond = np.zeros(vertices.shape[0], dtype=np.bool_)
    for k in range(vertices.shape[0]):
        v = vertices[k]
        for a in anchors:
            apart = 0.0
            for axis in range(3):
                apart += (positions[v, axis] - positions[a, axis]) ** 2
            flat = 0.0
            for axis in range(material.shape[1]):
                flat += (material[v, axis] - material[a, axis]) ** 2
            shaped = 0.0
            for axis in range(3):
                shaped += (rest_shape[v, axis] - rest_shape[a, axis]) ** 2
            if apart > stretch * stretch * max(flat, shaped):
                beyond[k] = True
                break
    return beyond


@njit(cache=True, inline='always')
def _spring_strain(positions, spring_vertices, rest_length, s):
    """l/l0 − 1 of spring s."""
    i = spring_vertices[s, 0]
    j = spring_vertices[s, 1]
    dx = positions[j, 0] - positions[i, 0]
    dy = positions[j, 1] - positions[i, 1]
    dz = positions[j, 2] - positions[i, 2]
    return np.sqrt(dx * dx + dy * dy + dz * dz) / rest_length[s] - 1.0


@njit(cache=True)
def any_squeezed(positions, spring_vertices, rest_length, compression_threshold):
    """Whether a spring is shorter than (1 − ``compression_threshold``) × its rest length:
    the check that most sub-steps end the buckling iterations with (a sheet not squeezed).
    On squared lengths, and it stops at the first such spring (129², hanging: 0.11 against
    0.26 ms for the sum of the excess it replaced)."""
    for s in range(spring_vertices.shape[0]):
        i = spring_vertices[s, 0]
        j = spring_vertices[s, 1]
        dx = positions[j, 0] - positions[i, 0]
        dy = positions[j, 1] - positions[i, 1]
        dz = positions[j, 2] - positions[i, 2]
        shortest = (1.0 - compression_threshold) * rest_length[s]
        if dx * dx + dy * dy + dz * dz < shortest * shortest:
            return True
    return False


@njit(cache=True, inline='always')
def _gripped_edge(start_positions, prediction, grip_probe, i, j):
    """x_j − x_i with a gripped end where its probe carries it (``prediction``)."""
    ix = prediction[i, 0] if grip_probe[i] >= 0 else start_positions[i, 0]
    iy = prediction[i, 1] if grip_probe[i] >= 0 else start_positions[i, 1]
    iz = prediction[i, 2] if grip_probe[i] >= 0 else start_positions[i, 2]
    jx = prediction[j, 0] if grip_probe[j] >= 0 else start_positions[j, 0]
    jy = prediction[j, 1] if grip_probe[j] >= 0 else start_positions[j, 1]
    jz = prediction[j, 2] if grip_probe[j] >= 0 else start_positions[j, 2]
    return jx - ix, jy - iy, jz - iz


@njit(cache=True)
def squeezed_before_bending(start_positions, prediction, grip_probe, gripping, spring_vertices,
                            rest_length, compression_threshold, table_top, probe_from, probe_to,
                            probe_radius, probe_active, reach):
    """Whether a spring is shorter than (1 − ``compression_threshold``) × its rest length in
    the inertial ``prediction`` where that is the sheet's doing: everywhere without a table
    (``table_top`` −inf); with one, where neither end lies on it (at or below ``table_top``,
    as the sub-step starts or in the prediction), or within ``reach`` × radius and the
    spring's rest length of an active probe's sweep (its centre's path from ``probe_from``
    to ``probe_to``); or in the sheet as the sub-step starts (``start_positions``; with
    ``gripping``, its gripped vertices where their probes carry them in ``prediction``).
    Simulator._squeezed_before_bending says why. Stops at the first such spring."""
    if table_top == -np.inf:
        return any_squeezed(prediction, spring_vertices, rest_length, compression_threshold)
    probing = False
    for k in range(probe_active.shape[0]):
        probing = probing or probe_active[k]
    for s in range(spring_vertices.shape[0]):
        i = spring_vertices[s, 0]
        j = spring_vertices[s, 1]
        shortest = (1.0 - compression_threshold) * rest_length[s]
        dx = start_positions[j, 0] - start_positions[i, 0]
        dy = start_positions[j, 1] - start_positions[i, 1]
        dz = start_positions[j, 2] - start_positions[i, 2]
        if gripping and (grip_probe[i] >= 0 or grip_probe[j] >= 0):
            dx, dy, dz = _gripped_edge(start_positions, prediction, grip_probe, i, j)
        if dx * dx + dy * dy + dz * dz < shortest * shortest:
            return True
        dx = prediction[j, 0] - prediction[i, 0]
        dy = prediction[j, 1] - prediction[i, 1]
        dz = prediction[j, 2] - prediction[i, 2]
        if dx * dx + dy * dy + dz * dz >= shortest * shortest:
            continue
        if min(min(start_positions[i, 2], start_positions[j, 2]),
               min(prediction[i, 2], prediction[j, 2])) > table_top:
            return True
        if not probing:
            continue
        mx = 0.5 * (prediction[i, 0] + prediction[j, 0])
        my = 0.5 * (prediction[i, 1] + prediction[j, 1])
        mz = 0.5 * (prediction[i, 2] + prediction[j, 2])
        for k in range(probe_active.shape[0]):
            if not probe_active[k]:
                continue
            # the nearest point of the centre's path
            px = probe_to[k, 0] - probe_from[k, 0]
            py = probe_to[k, 1] - probe_from[k, 1]
            pz = probe_to[k, 2] - probe_from[k, 2]
            ex = mx - probe_from[k, 0]
            ey = my - probe_from[k, 1]
            ez = mz - probe_from[k, 2]
            travel = px * px + py * py + pz * pz
            along = 0.0
            if travel > 0.0:
                along = min(max((ex * px + ey * py + ez * pz) / travel, 0.0), 1.0)
            ex -= along * px
            ey -= along * py
            ez -= along * pz
            near = reach * probe_radius[k] + rest_length[s]
            if ex * ex + ey * ey + ez * ez <= near * near:
                return True
    return False


@njit(cache=True)
def max_abs_strain(positions, spring_vertices, rest_length, spring_kind, kind):
    """Largest |l/l0 - 1| over the springs of one kind."""
    largest = 0.0
    for s in range(spring_vertices.shape[0]):
        if spring_kind[s] == kind:
            largest = max(largest, abs(_spring_strain(positions, spring_vertices,
                                                      rest_length, s)))
    return largest


@njit(cache=True)
def vertex_max_abs_strain(positions, spring_vertices, rest_length, spring_kind, kind):
    """(V,) the largest |l/l0 - 1| of the springs of one kind at each vertex."""
    largest = np.zeros(positions.shape[0])
    for s in range(spring_vertices.shape[0]):
        if spring_kind[s] == kind:
            strain = abs(_spring_strain(positions, spring_vertices, rest_length, s))
            for end in range(2):
                v = spring_vertices[s, end]
                largest[v] = max(largest[v], strain)
    return largest


@njit(cache=True)
def springs_shorter_than(positions, spring_vertices, rest_length, spring_kind, kind, ratio):
    """Indices, ascending, of the springs of one kind shorter than ``ratio`` × rest length
    (one pass, no (S, 3) temporaries: the damage check runs it every frame)."""
    short = np.empty(spring_vertices.shape[0], dtype=np.int64)
    count = 0
    for s in range(spring_vertices.shape[0]):
        if spring_kind[s] == kind and _spring_strain(positions, spring_vertices, rest_length,
                                                     s) < ratio - 1.0:
            short[count] = s
            count += 1
    return short[:count].copy()


@njit(cache=True)
def lift_squeezed(positions, inverse_mass, spring_vertices, rest_length, ground_height,
                  threshold):
    """Raise each free vertex lying on the table whose springs are squeezed by more than
    ``threshold`` by the height that would give a spring of its compression c its length
    back over a rise: l0 √(2c). A sheet pushed together on a table can only buckle up, and
    a flat one has no out-of-plane motion for the solve to amplify."""
    vertex_count = positions.shape[0]
    squeeze = np.zeros(vertex_count)
    reach = np.zeros(vertex_count)
    for s in range(spring_vertices.shape[0]):
        c = -_spring_strain(positions, spring_vertices, rest_length, s)
        if c <= threshold:
            continue
        for end in range(2):
            v = spring_vertices[s, end]
            if c > squeeze[v]:
                squeeze[v] = c
                reach[v] = rest_length[s]
    for v in range(vertex_count):
        if squeeze[v] > 0.0 and inverse_mass[v] > 0.0 and positions[v, 2] <= ground_height:
            positions[v, 2] = ground_height + reach[v] * np.sqrt(2.0 * squeeze[v])


@njit(cache=True)
def table_penetration(positions, ground_height):
    """Deepest any vertex sits below the table [m]."""
    deepest = 0.0
    for v in range(positions.shape[0]):
        deepest = max(deepest, ground_height - positions[v, 2])
    return deepest


@njit(cache=True)
def probe_penetration(positions, probe_center, probe_radius, probe_active, ground_height,
                      ground_enabled):
    """Deepest any vertex sits inside an active probe [m]. A probe pressed into the table is
    flattened there like a fingertip (its sphere cut by the table plane), so a vertex
    pinched on the table under it is at its surface, not inside it."""
    deepest = 0.0
    for v in range(positions.shape[0]):
        deepest = max(deepest, _probe_depth(positions, v, probe_center, probe_radius,
                                            probe_active, ground_height, ground_enabled))
    return deepest


@njit(cache=True)
def inside_probes(positions, probe_center, probe_radius, probe_active, ground_height,
                  ground_enabled, tolerance, inside):
    """Mark in ``inside`` the vertices deeper than ``tolerance`` [m] inside an active probe
    (flattened on the table as in ``probe_penetration``)."""
    for v in range(positions.shape[0]):
        inside[v] = _probe_depth(positions, v, probe_center, probe_radius, probe_active,
                                 ground_height, ground_enabled) > tolerance


@njit(cache=True, inline='always')
def _deepest_probe(positions, v, probe_center, probe_radius, probes, depth_share):
    """The one of ``probes`` (indices) whose surface vertex v is deepest below (the first
    of equals), if v is nearer than (1 − depth_share) of its radius to the centre of one
    of them; else -1."""
    deep = False
    deepest = np.inf
    found = -1
    for p in probes:
        dx = positions[v, 0] - probe_center[p, 0]
        dy = positions[v, 1] - probe_center[p, 1]
        dz = positions[v, 2] - probe_center[p, 2]
        distance = np.sqrt(dx * dx + dy * dy + dz * dz)
        deep = deep or distance < (1.0 - depth_share) * probe_radius[p]
        if distance - probe_radius[p] < deepest:
            deepest = distance - probe_radius[p]
            found = p
    return found if deep else -1


@njit(cache=True)
def contact_rows_hold(positions, probe_center, probe_radius, probe_active, ground_height,
                      ground_enabled, tolerance, pinned, row_vertex, row_is_contact,
                      multipliers, rising, depth_share, gripped):
    """Whether a solve's probe rows stand as they are: every contact row pushes (λ ≤ 0),
    no free vertex without a row sits deeper than ``tolerance`` [m] inside an active probe,
    and none but a gripped one nearer than (1 − depth_share) of its radius to the centre of
    one of the ``rising`` probes (indices; ``_deepest_probe``). Simulator.
    _settle_contact_rows changes the rows otherwise. One pass and no allocation but a mark
    per vertex: most iterations leave the rows alone."""
    for r in range(row_vertex.shape[0]):
        if row_is_contact[r] and not multipliers[r] <= 0.0:
            return False
    has_row = np.zeros(positions.shape[0], dtype=np.bool_)
    for r in range(row_vertex.shape[0]):
        has_row[row_vertex[r]] = True
    for v in range(positions.shape[0]):
        if pinned[v] or has_row[v]:
            continue
        if _probe_depth(positions, v, probe_center, probe_radius, probe_active,
                        ground_height, ground_enabled) > tolerance:
            return False
        if not gripped[v] and _deepest_probe(positions, v, probe_center, probe_radius,
                                             rising, depth_share) >= 0:
            return False
    return True


@njit(cache=True, inline='always')
def _sphere_plane(points, i, origin, o, center, c, radius, normal, surface, k):
    """Where the ray from ``origin[o]`` through ``points[i]`` leaves the sphere of
    ``radius`` round ``center[c]``, had they the same centre: the ray's unit direction into
    ``normal[k]`` (the sphere's normal there) and ``center[c]`` + radius · normal into
    ``surface[k]``."""
    length = 0.0
    for a in range(3):
        normal[k, a] = points[i, a] - origin[o, a]
        length += normal[k, a] * normal[k, a]
    length = max(np.sqrt(length), EPSILON_LENGTH)
    for a in range(3):
        normal[k, a] /= length
        surface[k, a] = center[c, a] + radius * normal[k, a]


@njit(cache=True, inline='always')
def _contact_plane(positions, v, probe_center, probe_radius, probe_active, ground_height,
                   ground_enabled, normal, surface, k):
    """Where vertex v touches the nearest active probe (the first of equals): the unit
    normal out of it into ``normal[k]``, the surface point nearest v into ``surface[k]``;
    under a probe pressed into the table, its flattened pad's face (the table plane,
    facing down)."""
    nearest = 0
    smallest = np.inf
    for p in range(probe_radius.shape[0]):
        if not probe_active[p]:
            continue
        dx = positions[v, 0] - probe_center[p, 0]
        dy = positions[v, 1] - probe_center[p, 1]
        dz = positions[v, 2] - probe_center[p, 2]
        gap = np.sqrt(dx * dx + dy * dy + dz * dz) - probe_radius[p]
        if gap < smallest:
            smallest = gap
            nearest = p
    _sphere_plane(positions, v, probe_center, nearest, probe_center, nearest,
                  probe_radius[nearest], normal, surface, k)
    if ground_enabled and surface[k, 2] < ground_height:
        normal[k, 0] = 0.0
        normal[k, 1] = 0.0
        normal[k, 2] = -1.0
        surface[k, 0] = positions[v, 0]
        surface[k, 1] = positions[v, 1]
        surface[k, 2] = ground_height


@njit(cache=True)
def contact_planes(positions, vertices, probe_center, probe_radius, probe_active,
                   ground_height, ground_enabled, normal, surface):
    """``_contact_plane`` of each of ``vertices`` into the rows of ``normal``, ``surface``."""
    for k in range(vertices.shape[0]):
        _contact_plane(positions, vertices[k], probe_center, probe_radius, probe_active,
                       ground_height, ground_enabled, normal, surface, k)


@njit(cache=True)
def settled_contact_rows(positions, start_positions, probe_from, probe_to, probe_radius,
                         probe_active, free_probes, rising, ground_height, ground_enabled,
                         tolerance, depth_share, pinned, gripped, row_vertex, row_direction,
                         row_value, row_is_contact, multipliers, table_reaction):
    """The probe rows of the next solve, where ``contact_rows_hold`` found that the last
    one's do not stand (Simulator._settle_contact_rows): the grips' rows and the contact
    rows that push (λ ≤ 0) as they were; then, in vertex order, a row for each free vertex
    without one deeper than ``tolerance`` inside one of the ``free_probes`` (on the
    nearest active probe's surface, ``_contact_plane``); then, in vertex order, one for
    each other free, ungripped vertex deep in one of the ``rising`` probes
    (``_deepest_probe``), on that probe's surface on the side the vertex came from (its
    start position against the probe's start centre, moved with it: from near its centre
    the way out is no way back). The added vertices' table reaction is zeroed. Returns
    (vertex, direction, value, is_contact)."""
    vertex_count = positions.shape[0]
    has_row = np.zeros(vertex_count, dtype=np.bool_)
    for r in range(row_vertex.shape[0]):
        has_row[row_vertex[r]] = True
    any_free = False
    for p in range(free_probes.shape[0]):
        any_free = any_free or free_probes[p]
    # 1: inside a free probe, 2: deep in a rising one (``deep_probe``)
    added = np.zeros(vertex_count, dtype=np.int8)
    deep_probe = np.full(vertex_count, -1, dtype=np.int64)
    near_count = 0
    deep_count = 0
    for v in range(vertex_count):
        if pinned[v] or has_row[v]:
            continue
        if any_free and _probe_depth(positions, v, probe_to, probe_radius, free_probes,
                                     ground_height, ground_enabled) > tolerance:
            added[v] = 1
            near_count += 1
        elif not gripped[v]:
            deep_probe[v] = _deepest_probe(positions, v, probe_to, probe_radius, rising,
                                           depth_share)
            if deep_probe[v] >= 0:
                added[v] = 2
                deep_count += 1
    kept = 0
    for r in range(row_vertex.shape[0]):
        if not row_is_contact[r] or multipliers[r] <= 0.0:
            kept += 1
    count = kept + near_count + deep_count
    vertex = np.empty(count, dtype=np.int64)
    direction = np.empty((count, 3))
    value = np.empty(count)
    is_contact = np.ones(count, dtype=np.bool_)
    k = 0
    for r in range(row_vertex.shape[0]):
        if not row_is_contact[r] or multipliers[r] <= 0.0:
            vertex[k] = row_vertex[r]
            for a in range(3):
                direction[k, a] = row_direction[r, a]
            value[k] = row_value[r]
            is_contact[k] = row_is_contact[r]
            k += 1
    surface = np.empty((count, 3))
    for kind in (1, 2):
        for v in range(vertex_count):
            if added[v] != kind:
                continue
            vertex[k] = v
            table_reaction[v] = 0.0
            if kind == 1:
                _contact_plane(positions, v, probe_to, probe_radius, probe_active,
                               ground_height, ground_enabled, direction, surface, k)
            else:
                p = deep_probe[v]
                _sphere_plane(start_positions, v, probe_from, p, probe_to, p, probe_radius[p],
                              direction, surface, k)
            value[k] = (direction[k, 0] * surface[k, 0] + direction[k, 1] * surface[k, 1]
                        + direction[k, 2] * surface[k, 2])
            k += 1
    return vertex, direction, value, is_contact


@njit(cache=True, inline='always')
def _probe_depth(positions, v, probe_center, probe_radius, probe_active, ground_height,
                 ground_enabled):
    """How deep vertex v sits inside the active probes [m] (≤ 0: outside)."""
    deepest = -np.inf
    for p in range(probe_radius.shape[0]):
        if not probe_active[p]:
            continue
        dx = positions[v, 0] - probe_center[p, 0]
        dy = positions[v, 1] - probe_center[p, 1]
        dz = positions[v, 2] - probe_center[p, 2]
        depth = probe_radius[p] - np.sqrt(dx * dx + dy * dy + dz * dz)
        if ground_enabled:
            depth = min(depth, positions[v, 2] - ground_height)
        deepest = max(deepest, depth)
    return deepest


@njit(cache=True)
def _mass_average(values, mass):
    """Σ m x / Σ m over the vertices (3,): the centre of mass, or its velocity."""
    total = 0.0
    average = np.zeros(3)
    for v in range(values.shape[0]):
        total += mass[v]
        for a in range(3):
            average[a] += mass[v] * values[v, a]
    return average / total


@njit(cache=True)
def angular_momentum(positions, velocities, mass):
    """The angular momentum (3,) [kg·m²/s] of the vertices about their centre of mass."""
    centre = _mass_average(positions, mass)
    drift = _mass_average(velocities, mass)
    momentum = np.zeros(3)
    for v in range(positions.shape[0]):
        rx = positions[v, 0] - centre[0]
        ry = positions[v, 1] - centre[1]
        rz = positions[v, 2] - centre[2]
        ux = velocities[v, 0] - drift[0]
        uy = velocities[v, 1] - drift[1]
        uz = velocities[v, 2] - drift[2]
        momentum[0] += mass[v] * (ry * uz - rz * uy)
        momentum[1] += mass[v] * (rz * ux - rx * uz)
        momentum[2] += mass[v] * (rx * uy - ry * ux)
    return momentum


@njit(cache=True)
def remove_angular_momentum(positions, velocities, mass, excess, h, vertical_only):
    """Turn the sheet rigidly about its centre of mass so that its angular momentum drops
    by ``excess`` [kg·m²/s]: v −= ω × r and x −= h ω × r, which take (I + h B) ω out of it
    (I: the inertia tensor about the centre; B = Σ m (r vᵀ − (r·v) 1): the turned positions'
    lever arms), so ω = (I + h B)⁻¹ excess; with ``vertical_only``, about the vertical
    through the centre (heights unchanged). Skipped for a sheet with no rotational inertia
    to speak of (a line)."""
    centre = _mass_average(positions, mass)
    system = np.zeros((3, 3))
    trace = 0.0
    for v in range(positions.shape[0]):
        r = (positions[v, 0] - centre[0], positions[v, 1] - centre[1],
             positions[v, 2] - centre[2])
        u = (velocities[v, 0], velocities[v, 1], velocities[v, 2])
        squared = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        along = r[0] * u[0] + r[1] * u[1] + r[2] * u[2]
        trace += 2.0 * mass[v] * squared
        for a in range(3):
            for b in range(3):
                diagonal = squared - h * along if a == b else 0.0
                system[a, b] += mass[v] * (diagonal - r[a] * r[b] + h * r[a] * u[b])
    if vertical_only:
        if system[2, 2] > 1e-9 * trace:
            _turn(positions, velocities, centre, 0.0, 0.0, excess[2] / system[2, 2], h)
        return
    # (I + h B)⁻¹ by cofactors: the same bits everywhere
    c00 = system[1, 1] * system[2, 2] - system[1, 2] * system[2, 1]
    c01 = system[1, 2] * system[2, 0] - system[1, 0] * system[2, 2]
    c02 = system[1, 0] * system[2, 1] - system[1, 1] * system[2, 0]
    c10 = system[0, 2] * system[2, 1] - system[0, 1] * system[2, 2]
    c11 = system[0, 0] * system[2, 2] - system[0, 2] * system[2, 0]
    c12 = system[0, 1] * system[2, 0] - system[0, 0] * system[2, 1]
    c20 = system[0, 1] * system[1, 2] - system[0, 2] * system[1, 1]
    c21 = system[0, 2] * system[1, 0] - system[0, 0] * system[1, 2]
    c22 = system[0, 0] * system[1, 1] - system[0, 1] * system[1, 0]
    determinant = system[0, 0] * c00 + system[0, 1] * c01 + system[0, 2] * c02
    if not abs(determinant) > 1e-9 * trace * trace * trace:
        return
    wx = (c00 * excess[0] + c10 * excess[1] + c20 * excess[2]) / determinant
    wy = (c01 * excess[0] + c11 * excess[1] + c21 * excess[2]) / determinant
    wz = (c02 * excess[0] + c12 * excess[1] + c22 * excess[2]) / determinant
    _turn(positions, velocities, centre, wx, wy, wz, h)


@njit(cache=True)
def _turn(positions, velocities, centre, wx, wy, wz, h):
    """v −= ω × r, x −= h ω × r about ``centre``."""
    for v in range(positions.shape[0]):
        rx = positions[v, 0] - centre[0]
        ry = positions[v, 1] - centre[1]
        rz = positions[v, 2] - centre[2]
        ux = wy * rz - wz * ry
        uy = wz * rx - wx * rz
        uz = wx * ry - wy * rx
        velocities[v, 0] -= ux
        velocities[v, 1] -= uy
        velocities[v, 2] -= uz
        positions[v, 0] -= h * ux
        positions[v, 1] -= h * uy
        positions[v, 2] -= h * uz


@njit(cache=True)
def slide_paths(velocities, dt, recent, slot, paths):
    """Each vertex's way over the last frames: ``recent`` (F, V) holds its |v| dt [m] of
    each of F frames, ``paths`` (V,) their sums. This frame's goes into row ``slot``,
    replacing the oldest. Returns the longest way and the largest |v| [m/s] now."""
    longest = 0.0
    fastest = 0.0
    for i in range(velocities.shape[0]):
        speed = np.sqrt(velocities[i, 0] ** 2 + velocities[i, 1] ** 2 + velocities[i, 2] ** 2)
        paths[i] += speed * dt - recent[slot, i]
        recent[slot, i] = speed * dt
        longest = max(longest, paths[i])
        fastest = max(fastest, speed)
    return longest, fastest


@njit(cache=True)
def all_finite(values):
    for x in values.ravel():
        if not np.isfinite(x):
            return False
    return True


@njit(cache=True)
def accumulate_probe_compression(positions, normals, frame_motion, spring_vertices,
                                 rest_length, springs, probe_start, probe_end, probe_radius,
                                 probe_active, grip_probe, reach, compression):
    """Add to ``compression[s]`` the compression the probes' motion over one frame imposes
    on each listed spring (core/probe_compression.py says why this one). Each vertex gets a
    push u, of which only the part in the sheet's tangent plane counts (``normals``: the
    sheet's unit vertex normals; a push straight into the sheet does not compress it):
    - a probe that pinches the sheet against the table (``grip_probe[v] == p`` for some v)
      pushes the vertices it pinches by its travel Δc;
    - any other probe pushes a vertex within ``reach`` × radius of its end centre by
      u = max(0, Δc · n) n (n: the contact normal).
    The spring (i, j) shortens by (u_i − u_j) · (x_j − x_i)/l, counted when > 0, over l0.
    Less the sheet's give: how much further apart the ends actually moved over the frame
    (``frame_motion``) than the pushes alone would have put them. Sheet that gets out of
    the way of a probe, as a sheet dragged over the table or sliding over a probe does,
    relieves the push instead of taking it."""
    vertex_count = positions.shape[0]
    probe_count = probe_radius.shape[0]
    pinching = np.zeros(probe_count, dtype=np.bool_)
    for v in range(vertex_count):
        if grip_probe[v] >= 0:
            pinching[grip_probe[v]] = True
    push = np.zeros((vertex_count, 3))
    pushed = np.zeros(vertex_count, dtype=np.bool_)
    for p in range(probe_count):
        if not probe_active[p]:
            continue
        limit = reach * probe_radius[p]
        tx = probe_end[p, 0] - probe_start[p, 0]
        ty = probe_end[p, 1] - probe_start[p, 1]
        tz = probe_end[p, 2] - probe_start[p, 2]
        for v in range(vertex_count):
            if pinching[p]:
                if grip_probe[v] != p:
                    continue
                ux = tx
                uy = ty
                uz = tz
            else:
                dx = positions[v, 0] - probe_end[p, 0]
                dy = positions[v, 1] - probe_end[p, 1]
                dz = positions[v, 2] - probe_end[p, 2]
                distance = np.sqrt(dx * dx + dy * dy + dz * dz)
                if distance > limit or distance < 1e-12:
                    continue
                normal_travel = (tx * dx + ty * dy + tz * dz) / distance
                if normal_travel <= 0.0:
                    continue
                scale = normal_travel / distance
                ux = scale * dx
                uy = scale * dy
                uz = scale * dz
            pushed[v] = True
            across = ux * normals[v, 0] + uy * normals[v, 1] + uz * normals[v, 2]
            push[v, 0] += ux - across * normals[v, 0]
            push[v, 1] += uy - across * normals[v, 1]
            push[v, 2] += uz - across * normals[v, 2]
    for n in range(springs.shape[0]):
        s = springs[n]
        i = spring_vertices[s, 0]
        j = spring_vertices[s, 1]
        if not (pushed[i] or pushed[j]):
            continue
        ux = push[i, 0] - push[j, 0]
        uy = push[i, 1] - push[j, 1]
        uz = push[i, 2] - push[j, 2]
        dx = positions[j, 0] - positions[i, 0]
        dy = positions[j, 1] - positions[i, 1]
        dz = positions[j, 2] - positions[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length < 1e-12:
            continue
        shortening = (ux * dx + uy * dy + uz * dz) / length
        if shortening > 0.0:
            # the way the sheet got out of the push: how much more the ends moved apart
            # than the pushes alone would have them (never less: that is the push's own)
            give = 0.0
            for axis in range(3):
                delta = (dx, dy, dz)[axis] / length
                give += delta * ((frame_motion[j, axis] - push[j, axis])
                                 - (frame_motion[i, axis] - push[i, axis]))
            shortening -= max(0.0, give)
        if shortening > 0.0:
            compression[s] += shortening / rest_length[s]
