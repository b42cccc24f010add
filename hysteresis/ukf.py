"""Active modelling: online estimation of the model error with an unscented Kalman filter
(seed 000, eq. 12-18, initial values eq. 29).

The reference model is a fitted :class:`~hysteresis.coleman_hodgdon.ColemanHodgdonModel`. The
filter's state is ``X_k = [alpha_k, f_h(k)]`` (eq. 17): the actual output and the model error,
an additive *rate* (output units per second) in the model's derivative, modelled as a random walk
(eq. 15). Prediction is the paper's discrete model (eq. 16 / eq. 18)::

    alpha_k = alpha_(k-1) + Ts [A |v_k| (C (u_k - O_u) - (alpha_(k-1) - O_y)) + B v_k + f_h(k-1)]
    f_h(k)  = f_h(k-1)
    Y_k     = alpha_k + V_k,            v_k = (u_k - u_(k-1)) / Ts

with filterpy's ``UnscentedKalmanFilter`` and ``MerweScaledSigmaPoints``. The enhanced estimate
is the filtered ``alpha_k``; ``f_h`` says how fast (and in which direction) reality leaves the
reference model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from hysteresis.base import FloatArray, HysteresisError, as_1d
from hysteresis.coleman_hodgdon import ColemanHodgdonModel, ColemanHodgdonState

__all__ = [
    "PAPER_P0", "PAPER_Q0", "PAPER_R0", "ActiveModelUKF", "UKFResult", "simulate_with_model_error",
]

# seed 000 eq. 29
PAPER_P0 = ((10.0, 0.0), (0.0, 10.0))
PAPER_Q0 = ((5.0, 0.0), (0.0, 15.0))
PAPER_R0 = 0.0001


@dataclass(frozen=True)
class UKFResult:
    """Per-sample outputs of :meth:`ActiveModelUKF.run`."""

    estimate: FloatArray  # enhanced estimate alpha_EstM (filtered output)
    f_h: FloatArray  # estimated model error (output units per second)
    model: FloatArray  # open-loop reference model output alpha_Model
    f_h_std: FloatArray  # posterior standard deviation of f_h


class ActiveModelUKF:
    """Model-error-enhanced estimator of seed 000 around a fitted Coleman-Hodgdon model.

    Args:
        model: fitted reference model (eq. 10-11).
        dt: sample time Ts in seconds (the rig's control tick is 10 ms).
        P0, Q, R: initial covariance, process noise of [U_k, h_k] and measurement noise
            (defaults: the paper's eq. 29).
        sigma_alpha, sigma_beta, sigma_kappa: MerweScaledSigmaPoints parameters. The process
            and measurement models are linear in the state, so any valid choice gives the same
            estimate; (1, 2, 0) places the points at X +/- sqrt(2 P).
    """

    def __init__(
        self,
        model: ColemanHodgdonModel,
        *,
        dt: float = 0.01,
        P0: Any = PAPER_P0,
        Q: Any = PAPER_Q0,
        R: float = PAPER_R0,
        sigma_alpha: float = 1.0,
        sigma_beta: float = 2.0,
        sigma_kappa: float = 0.0,
    ) -> None:
        model.check_fitted()
        if not dt > 0:
            raise HysteresisError(f"dt must be positive, got {dt}")
        self.model = model
        self.dt = float(dt)
        self.P0 = np.array(P0, dtype=np.float64).reshape(2, 2)
        self.Q = np.array(Q, dtype=np.float64).reshape(2, 2)
        self.R = float(R)
        if not self.R > 0:
            raise HysteresisError(f"R must be positive, got {R}")
        self._a, self._b, self._c, self._k = (float(v) for v in (*model.params_, model.k_))
        points = MerweScaledSigmaPoints(2, alpha=sigma_alpha, beta=sigma_beta, kappa=sigma_kappa)
        self._ukf = UnscentedKalmanFilter(
            dim_x=2, dim_z=1, dt=self.dt, fx=self._fx, hx=self._hx, points=points
        )
        self._u_prev = 0.0
        self._model_state: ColemanHodgdonState | None = None
        self.reset(0.0)

    # eq. 18, third line: the sigma points through the discrete model (v and u are fx_args)
    def _fx(self, x: FloatArray, dt: float, *, v: float, u: float) -> FloatArray:
        a_, b_, c_, k = self._a, self._b, self._c, self._k
        alpha = x[0] + dt * (a_ * abs(v) * (c_ * u - x[0] + k) + b_ * v + x[1])
        return np.array([alpha, x[1]])

    @staticmethod
    def _hx(x: FloatArray) -> FloatArray:
        return np.array([x[0]])

    def _start(self, u0: float, y0: float | None) -> ColemanHodgdonState:
        """The reference model's state at input u0: its rest output, or ``y0`` when given."""
        if y0 is None:
            return self.model.initial_state(float(u0))
        return ColemanHodgdonState(float(u0), float(y0))

    def reset(self, u0: float, y0: float | None = None, f_h0: float = 0.0) -> None:
        """Start at input u0 with output y0 (default: the reference model's rest output)."""
        st = self._start(u0, y0)
        self._model_state = st
        self._ukf.x = np.array([st.y, float(f_h0)])
        self._ukf.P = self.P0.copy()
        self._ukf.Q = self.Q.copy()
        self._ukf.R = np.array([[self.R]])
        self._u_prev = float(u0)

    def step(self, u: float, y_measured: float) -> tuple[float, float]:
        """One control tick: predict with the new input, update with the measurement.

        Returns (enhanced output estimate, f_h). A NaN measurement (missed camera frame)
        skips the update.
        """
        u = float(u)
        v = (u - self._u_prev) / self.dt
        self._u_prev = u
        self._ukf.predict(v=v, u=u)
        if np.isfinite(y_measured):
            self._ukf.update(np.array([float(y_measured)]))
        return float(self._ukf.x[0]), float(self._ukf.x[1])

    @property
    def f_h_std(self) -> float:
        return float(np.sqrt(max(self._ukf.P[1, 1], 0.0)))

    def run(self, u: Any, y_measured: Any, *, y0: float | None = None) -> UKFResult:
        """Filter a whole record (starting at rest at u[0], or at output y0)."""
        uu = as_1d(u, "u")
        yy = np.asarray(y_measured, dtype=np.float64)  # NaN allowed: a missed frame
        if yy.shape != uu.shape:
            raise HysteresisError(
                f"u and y_measured differ in shape: {uu.shape} vs {yy.shape}")
        self.reset(float(uu[0]), y0=y0)
        n = uu.size
        est = np.empty(n)
        fh = np.empty(n)
        fstd = np.empty(n)
        for i in range(n):
            est[i], fh[i] = self.step(float(uu[i]), float(yy[i]))
            fstd[i] = self.f_h_std
        model_out = self.model.predict(uu, state=self._start(float(uu[0]), y0))
        return UKFResult(estimate=est, f_h=fh, model=model_out, f_h_std=fstd)


def simulate_with_model_error(
    model: ColemanHodgdonModel, u: Any, f_h: Any, *, dt: float = 0.01, y0: float | None = None
) -> FloatArray:
    """The paper's "actual model" (eq. 14/16 without noise): the reference dynamics plus an
    additive model-error rate ``f_h`` (scalar or per-sample array), Euler-discretised at ``dt``.
    Used to test that the filter recovers an injected error."""
    uu = np.asarray(u, dtype=np.float64)
    fh = np.broadcast_to(np.asarray(f_h, dtype=np.float64), uu.shape)
    a_, b_, c_ = (float(v) for v in model.params_)
    k = model.k_
    y = model.initial_state(float(uu[0])).y if y0 is None else float(y0)
    out = np.empty_like(uu)
    up = float(uu[0])
    for i in range(uu.size):
        v = (uu[i] - up) / dt
        y = y + dt * (a_ * abs(v) * (c_ * uu[i] - y + k) + b_ * v + fh[i])
        up = float(uu[i])
        out[i] = y
    return out
