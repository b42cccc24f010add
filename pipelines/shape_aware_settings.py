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

    #: ``poly`` (ridge regression on theta^a kappa^b) or ``rbf`` (thin-plate spline through the
    #: training shapes).
    method: str = "poly"
    #: Highest power of theta in the poly basis (capped by the number of training angles).
    angle_degree: int = 3
    #: Highest power of kappa in the poly basis (capped by the number of training radii).
    curvature_degree: int = 1
    #: Ridge penalty on the non-constant poly coefficients (features scaled to [0, 1]); 0 = plain
    #: least squares.
    ridge: float = 1.0e-3
    #: Smoothing of the rbf interpolant; 0 = exact interpolation.
    rbf_smoothing: float = 0.0
