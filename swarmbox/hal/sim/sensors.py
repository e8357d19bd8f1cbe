"""GNSS receivers and position estimators of a simulated fleet, vectorized.

The estimator is what PX4's EKF2 does for position, reduced to its observable behaviour:

- **Prediction** with a perfect IMU (the true acceleration). Kept in error-state form: the estimate
  is ``truth + err`` and ``err`` only changes on a GNSS correction, which is exactly what integrating
  the true acceleration from the corrected estimate gives. Only positions are corrected, so the
  velocity estimate is the true velocity.
- **Correction** toward each GNSS fix with a fixed gain (a complementary filter), behind an
  **innovation gate** on the horizontal innovation.
- **Reset**: a fix rejected when none was accepted for ``est_reset_timeout_s`` (EKF2's no-aiding
  timeout; a GNSS outage counts too) moves the estimate to the fix and increments the reset counter.

So a slowly drifting GNSS is followed (the vehicle, flying on the estimate, drifts physically); a fast
drift is rejected (the GNSS − estimate discrepancy grows) until the reset, when the vehicle jumps. A
constant drift rate r settles at a lag of r·T·(1 − gain)/gain behind the fixes (T = fix period), so
with the defaults drifts faster than about 1.6 m/s outrun the 3 m gate.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from swarmbox.hal.sim.params import SimParams

#: (drone index, reset count, jump in metres) for each estimator reset of one fix.
Reset = tuple[int, int, float]


class GnssEstimator:
    """GNSS + estimator state for N vehicles; all randomness comes from ``rng``.

    Fault inputs (public, neutral by default): ``offset_ned_m`` (N,3) is added to every fix,
    ``noise_scale`` (N,) multiplies the noise, ``available`` (N,) False stops the fixes. Internal
    state is axis-first, (3, N), like the rest of the simulator.
    """

    def __init__(self, n: int, p: SimParams, rng: np.random.Generator) -> None:
        self.p, self._rng = p, rng
        self.period_s = 1.0 / p.gnss_rate_hz
        self._sigma = np.array([[p.gnss_sigma_h_m], [p.gnss_sigma_h_m], [p.gnss_sigma_v_m]])
        self.offset_ned_m = np.zeros((n, 3))
        self.noise_scale = np.ones(n)
        self.available = np.ones(n, dtype=bool)
        self.err_ned_m = np.zeros((3, n))         # estimate − truth
        self.fix_ned_m = np.full((3, n), np.nan)   # latest fix (NaN before the first)
        self.seq = np.zeros(n, dtype=np.int64)
        self.resets = np.zeros(n, dtype=np.int64)
        self._last_accept_s = np.zeros(n)
        self._next_fix_s = self.period_s
        self._noise, self._innov, self._fix = np.zeros((3, n)), np.zeros((3, n)), np.zeros((3, n))
        self._ok = np.zeros(n, dtype=bool)        # accepted by the last fix (the compiled path's)

    def due(self, t_s: float) -> bool:
        """True when a fix is due at ``t_s`` (call :meth:`fix` then)."""
        return t_s >= self._next_fix_s - 1e-9

    def fix(self, t_s: float, true_pos_ned_m: np.ndarray, jit: ModuleType | None = None) -> list[Reset]:
        """Take a fix for every available receiver and correct the estimates; returns the resets.

        ``jit``: the compiled kernel module (:mod:`swarmbox.hal.sim.kernel`), which computes the same."""
        self._next_fix_s = max(self._next_fix_s + self.period_s, t_s + 0.5 * self.period_s)
        err_fix, innov, avail = self._noise, self._innov, self.available
        self._rng.standard_normal(out=err_fix)      # drawn for all: streams stay aligned
        if jit is not None:
            rejected = jit.gnss_correct(*self.kernel_args(t_s, true_pos_ned_m))
            return self._resets(t_s, avail & ~self._ok) if rejected else []
        err_fix *= self._sigma
        err_fix *= self.noise_scale
        err_fix += self.offset_ned_m.T              # now fix − truth
        np.subtract(err_fix, self.err_ned_m, innov)   # fix − estimate
        ok = avail & (np.hypot(innov[0], innov[1]) <= self.p.est_gate_m)
        self.err_ned_m += innov * (self.p.est_gain * ok)
        np.copyto(self._last_accept_s, t_s, where=ok)
        np.add(true_pos_ned_m, err_fix, self._fix)
        np.copyto(self.fix_ned_m, self._fix, where=avail)
        self.seq += avail
        rejected = avail & ~ok
        return self._resets(t_s, rejected) if np.count_nonzero(rejected) else []

    def kernel_args(self, t_s: float, true_pos_ned_m: np.ndarray) -> tuple:
        """The arguments of ``fleet_jit.gnss_correct`` (no side effect)."""
        return (self._noise, self._sigma, self.noise_scale, self.offset_ned_m, self.err_ned_m, self._innov,
                self.p.est_gate_m, self.p.est_gain, self.available, self._ok, self._last_accept_s, t_s,
                true_pos_ned_m, self.fix_ned_m, self.seq)

    def _resets(self, t_s: float, rejected: np.ndarray) -> list[Reset]:
        due = rejected & (t_s - self._last_accept_s >= self.p.est_reset_timeout_s)
        out: list[Reset] = []
        for i in np.flatnonzero(due).tolist():
            jump_m = float(np.linalg.norm(self._innov[:, i]))
            self.err_ned_m[:, i] = self._noise[:, i]
            self.resets[i] += 1
            self._last_accept_s[i] = t_s
            out.append((i, int(self.resets[i]), jump_m))
        return out

    def ready(self, t_s: float) -> np.ndarray:
        """Per vehicle: estimator initialised (a fix received, start-up time elapsed)."""
        return (self.seq > 0) & (t_s >= self.p.est_init_s)
