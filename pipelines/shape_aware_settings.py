"""The shape-aware model's hyper-parameters as a settings node.

Shared by the unseen_shape stage (``estimator``) and the compensation experiments
(``seed001.shape_aware.estimator``); a leaf module, so each stage's settings can import it
without importing the other stage's.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class ShapeAwareEstimator:
    """Hyper-parameters of :class:`hysteresis.shape_aware.ShapeAwareModel`, with its defaults:
    features theta (curve angle, rad) and kappa = 1/R; ridge regression on
    theta^0..angle_degree x kappa^0..curvature_degree (``method: poly``) or a thin-plate
    spline (``method: rbf``)."""

    method: str = "poly"
    angle_degree: int = 3
    curvature_degree: int = 1
    ridge: float = 1.0e-3
    rbf_smoothing: float = 0.0
