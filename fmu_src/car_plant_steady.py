"""Steady turn of the car plant on a flat road, solved on the plant's own equations.

:func:`steady_turn` finds the rest point of :meth:`CarPlantModel.derivatives
<latobs.fmu_src.car_plant.CarPlantModel.derivatives>` at a given speed and lateral acceleration:
the validation scenarios calibrate their steer angle with it (``steady-turn``), so the scenario
and the plant can never disagree about the physics. It lives beside the plant model rather than
in the validation package because it is a property of the plant's equations (one source for the
maths); like the plant it is standard library only.
"""
from __future__ import annotations

import math

from .car_plant import G, CarPlantModel
from .linalg import total

__all__ = ["steady_turn"]

_TOL = 1e-14      # converged: largest scaled residual
_ACCEPT = 1e-9    # a steady turn: |S - m ay| <= 1e-9 m g and every scaled residual <= 1e-9


def steady_turn(data: dict, vx: float, ay: float, params: dict | None = None) -> dict:
    """Steady turn of :class:`CarPlantModel` (``data``, ``params`` as for the model) on a flat road
    at the constant speed ``vx`` (m/s) with the lateral acceleration output ``ay`` = S/m (m/s^2).

    In a steady turn every derivative vanishes with roll rate 0, so r = ay/vx (E2) and the
    unknowns are the lateral velocity vy, the road-wheel angle delta, the roll angle phi and the
    four tire forces at their relaxed values (F = F_ss, E7). They are found by damped Newton
    from the linear bicycle's steady state, on the plant's derivatives with a central-difference
    Jacobian. The relaxed steady state does not depend on the relaxation length: a plant with
    algebraic tires (sigma <= 0) is solved with sigma = 1 m (its own one-pass load-transfer loop
    shifts ay slightly from this state).

    Returns {delta, vy, beta, yaw_rate, roll_angle, ay, alpha_f, alpha_r, Fyf, Fyr, F, iterations}
    (SI units, beta = atan(vy/vx) at the roll axis, alpha_* the axle means as the plant reports
    them, F the wheel forces fl, fr, rl, rr). Raises ValueError when no steady turn exists (ay beyond the tires' grip) or for a
    speed <= the plant's V_SLIP_MIN or a non-finite ay.
    """
    vmin = CarPlantModel.V_SLIP_MIN
    if not (math.isfinite(vx) and vx > vmin):
        raise ValueError(f"a steady turn needs a speed > {vmin} m/s, got {vx}")
    if not math.isfinite(ay):
        raise ValueError(f"a steady turn needs a finite lateral acceleration, got {ay}")
    vx, ay = float(vx), float(ay)
    plant = CarPlantModel(data, params)
    if not plant.params["sigma"] > 0.0:
        plant = CarPlantModel(data, {**(params or {}), "sigma": 1.0})
    v = plant.vehicle
    m, lf, lr, hr, Kr = v["m"], v["lf"], v["lr"], v["hr"], v["Kr"]
    L = lf + lr
    r = ay / vx
    k = max(vx, CarPlantModel.V_RELAX_MIN) / plant.params["sigma"]     # E7: F' = k (F_ss - F)
    # residual scales: vy' as a force (/ m g), r' and phi'' as moments (/ m g L, / m g hr), F' as a force
    scale = (1.0 / G, v["Iz"] / (m * G * L), v["Ix"] / (m * G * hr), 1.0 / (k * m * G))

    def state(z):
        vy, _, phi, *F = z
        return [vy, r, phi, 0.0, *F]

    def residual(z):
        d = plant.derivatives(state(z), {"delta": z[1], "vx": vx, "bank_angle": 0.0})
        return [d[0] * scale[0], d[1] * scale[1], d[3] * scale[2]] + [x * scale[3] for x in d[4:]]

    # start: the linear bicycle's steady state, forces split evenly per axle, roll from E1
    Cf, Cr = plant.params["scale_f"] * v["Cf"], plant.params["scale_r"] * v["Cr"]
    k_us = m / L * (lr / Cf - lf / Cr)
    Ff, Fr = m * ay * lr / L, m * ay * lf / L
    z = [vx * (lr * r / vx - m * ay * lf / (L * Cr)), ay * (L + k_us * vx**2) / vx**2,
         hr * m * ay / (Kr - m * G * hr), Ff / 2, Ff / 2, Fr / 2, Fr / 2]
    steps = (1e-6 * vx, 1e-7, 1e-7) + (1e-6 * m * G,) * 4
    res = residual(z)
    iterations = 0
    for iterations in range(1, 60):
        J = [[0.0] * 7 for _ in range(7)]
        for j, h in enumerate(steps):
            zp, zm = list(z), list(z)
            zp[j] += h
            zm[j] -= h
            rp, rm = residual(zp), residual(zm)
            for i in range(7):
                J[i][j] = (rp[i] - rm[i]) / (2 * h)
        try:
            dz = _solve(J, [-x for x in res])
        except ZeroDivisionError:
            break
        lam, size = 1.0, max(map(abs, res))
        while True:   # damped Newton: never accept a step that makes the residual larger
            trial_z = [a + lam * b for a, b in zip(z, dz)]
            trial = residual(trial_z)
            if max(map(abs, trial)) < size or lam < 1e-6:
                break
            lam *= 0.5
        z, res = trial_z, trial
        if max(map(abs, res)) < _TOL:
            break
    u = {"delta": z[1], "vx": vx, "bank_angle": 0.0}
    ts = plant.tire_state(state(z), u)
    if not (all(map(math.isfinite, z)) and abs(ts["S"] - m * ay) <= _ACCEPT * m * G
            and max(map(abs, res)) <= _ACCEPT):
        raise ValueError(f"CarPlant has no steady turn at vx = {vx} m/s, ay = {ay} m/s^2 "
                         f"(residual S - m ay = {ts['S'] - m * ay:.3g} N, yaw moment Mz = "
                         f"{res[1] * m * G * L:.3g} N m): beyond the tires' grip?")
    return {"delta": z[1], "vy": z[0], "beta": math.atan(z[0] / vx), "yaw_rate": r, "roll_angle": z[2],
            "ay": ts["S"] / m, "alpha_f": ts["alpha_f"], "alpha_r": ts["alpha_r"], "Fyf": ts["Fyf"],
            "Fyr": ts["Fyr"], "F": tuple(z[3:]), "iterations": iterations}


def _solve(A, b):
    """x with A x = b, Gaussian elimination with partial pivoting (A small and dense, copied)."""
    n = len(b)
    M = [list(row) + [bi] for row, bi in zip(A, b)]
    for c in range(n):
        p = max(range(c, n), key=lambda i: abs(M[i][c]))
        if M[p][c] == 0.0:
            raise ZeroDivisionError("singular Jacobian")
        M[c], M[p] = M[p], M[c]
        for i in range(c + 1, n):
            f = M[i][c] / M[c][c]
            for j in range(c, n + 1):
                M[i][j] -= f * M[c][j]
    x = [0.0] * n
    for i in range(n - 1, -1, -1):
        x[i] = (M[i][n] - total(M[i][j] * x[j] for j in range(i + 1, n))) / M[i][i]
    return x
