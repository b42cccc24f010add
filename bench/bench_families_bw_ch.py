"""Bouc-Wen and Coleman-Hodgdon benchmark (`make bench`).

* forward simulation (samples per second), exact inverse (microseconds per step) and one UKF
  tick (seed 000 eq. 18), on an 80 s record at 100 Hz;
* fit time on that 8000-sample record: ours (Bouc-Wen varpro, Coleman-Hodgdon varpro) against
  the papers' identification (raw BFGS on eq. 5 from a near start; GA on eq. 26), as ratios;
* the Bouc-Wen optimiser table of seed 002 IV-A over its 18 cases (success/18, median time),
  ours against every paper method, for the paper's initial guesses and for guesses drawn from
  the whole GA box. Budgets are cut to keep the bench near a minute (scipy maxiter 300, GA
  5 x 6 members x 40 generations, PSO 15 particles x 40 iterations); the paper's full
  budgets run with ``python -m hysteresis.optimisers``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from hysteresis.bouc_wen import BoucWenModel, bw_simulate
from hysteresis.coleman_hodgdon import PAPER_PARAMS, ColemanHodgdonModel, ch_simulate
from hysteresis.optimisers import METHODS, compare_optimisers, paper_cases
from hysteresis.ukf import ActiveModelUKF

BW_TRUE = np.array([0.8, 0.5, 0.1, 2.0, 0.9, -1.5])
BENCH_BUDGET = {"maxiter": 300, "ga_popsize": 5, "ga_maxiter": 40, "pso_particles": 15,
                "pso_iters": 40}


def _record() -> np.ndarray:
    """80 s at 100 Hz: the pipeline's decaying sinusoid in mm (+/- 6 mm)."""
    t = np.arange(8000) * 0.01
    return 6.0 * np.exp(-t / 40.0) * np.sin(2 * np.pi * 0.25 * t)


def _best_of(fn: Any, repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _optimiser_table(init: str, methods: tuple[str, ...]) -> dict[str, Any]:
    res = compare_optimisers(paper_cases(18, init=init), methods=methods, progress=False,
                             **BENCH_BUDGET)
    s = res["methods"]
    ours = s["ours"]
    table: dict[str, Any] = {}
    for m, row in s.items():
        table[m] = {
            "success": f"{row['success']}/{row['n']}",
            "success_count": row["success"],
            "mse_median": row["mse_median"],
            "time_median_s": row["time_median_s"],
            # > 1: the paper method is slower than ours / succeeds less often
            "time_ratio_vs_ours": row["time_median_s"] / ours["time_median_s"],
            # None when the method never succeeds (strict JSON has no infinity)
            "success_ratio_ours_over_method": (
                ours["success"] / row["success"] if row["success"] else None),
        }
    return table


def run() -> dict[str, Any]:
    u = _record()
    y_bw = bw_simulate(u, BW_TRUE)
    y_ch = ch_simulate(u, *PAPER_PARAMS, origin=(0.0, 0.0))
    out: dict[str, Any] = {"record_samples": int(u.size)}

    # -- fit times on the 8000-sample record (first call compiles; excluded) ------------------
    bw = BoucWenModel().fit(u, y_bw)
    bw_paper = BoucWenModel(method="bfgs", fit_offset=False, fit_max_samples=10**9)
    bw_paper.fit(u[:100], y_bw[:100], x0=BW_TRUE * 1.2)
    ch = ColemanHodgdonModel().fit(u, y_ch)
    chv = ColemanHodgdonModel(method="varpro").fit(u, y_ch)
    t_bw = _best_of(lambda: BoucWenModel().fit(u, y_bw))
    t_bw_paper = _best_of(lambda: bw_paper.fit(u, y_bw, x0=BW_TRUE * 1.2), repeat=1)
    t_ch_ga = _best_of(lambda: ColemanHodgdonModel().fit(u, y_ch))
    t_ch_vp = _best_of(lambda: ColemanHodgdonModel(method="varpro").fit(u, y_ch))
    out["fit_time_s"] = {
        "bouc_wen_ours_varpro": t_bw,
        "bouc_wen_paper_bfgs_full_record": t_bw_paper,
        "bouc_wen_paper_over_ours": t_bw_paper / t_bw,
        "coleman_hodgdon_ga_default": t_ch_ga,
        "coleman_hodgdon_ours_varpro": t_ch_vp,
        "coleman_hodgdon_ga_over_varpro": t_ch_ga / t_ch_vp,
        "bouc_wen_paper_bfgs_train_mse": bw_paper.sse_ / bw_paper.n_samples_,
        "bouc_wen_ours_train_mse": bw.sse_ / bw.n_samples_,
    }

    # -- forward simulation and inverses ------------------------------------------------------
    t_sim_bw = _best_of(lambda: bw.predict(u), repeat=5)
    t_sim_ch = _best_of(lambda: ch.predict(u), repeat=5)
    yd_bw, yd_ch = bw.predict(u), chv.predict(u)
    t_inv_bw = _best_of(lambda: bw.invert(yd_bw), repeat=3)
    t_ff_bw = _best_of(lambda: bw.invert(yd_bw, method="feedforward"), repeat=3)
    t_inv_ch = _best_of(lambda: chv.invert(yd_ch), repeat=3)
    st: dict[str, float] | None = None

    def _steps() -> None:
        nonlocal st
        st = None
        for x in u[:2000]:
            _, st = bw.step(float(x), st)

    t_step = _best_of(_steps, repeat=2) / 2000
    out["forward_samples_per_s"] = {
        "bouc_wen": u.size / t_sim_bw, "coleman_hodgdon": u.size / t_sim_ch,
    }
    out["per_step_us"] = {
        "bouc_wen_exact_inverse": 1e6 * t_inv_bw / u.size,
        "bouc_wen_feedforward_eq4": 1e6 * t_ff_bw / u.size,
        "bouc_wen_exact_over_feedforward": t_inv_bw / t_ff_bw,
        "coleman_hodgdon_exact_inverse": 1e6 * t_inv_ch / u.size,
        "bouc_wen_python_step_call": 1e6 * t_step,
    }
    ukf = ActiveModelUKF(chv)
    n_ukf = 1000
    t_ukf = _best_of(lambda: ukf.run(u[:n_ukf], y_ch[:n_ukf]), repeat=1)
    out["per_step_us"]["ukf_tick_filterpy"] = 1e6 * t_ukf / n_ukf

    # -- seed 002 IV-A optimiser table ---------------------------------------------------------
    out["bouc_wen_optimisers_budget"] = dict(BENCH_BUDGET)
    out["bouc_wen_optimisers_paper_init"] = _optimiser_table("paper", METHODS)
    # GA and PSO ignore the initial guess (they search the box), so they are not rerun.
    local = tuple(m for m in METHODS if m not in ("ga", "pso"))
    out["bouc_wen_optimisers_box_init"] = _optimiser_table("box", local)
    return out


if __name__ == "__main__":  # pragma: no cover
    import json

    print(json.dumps(run(), indent=1))
