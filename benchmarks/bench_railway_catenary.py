"""The thesis's parabola against the exact catenary: where does the parabola stop being good enough?

For level supports and the same mid-span sag, the largest vertical gap between the parabola
z = 4 s x (L - x) / L^2 and the catenary a (cosh((x - L/2) / a) - cosh(L / 2a)) is measured
numerically (:func:`bpy_pipeline.builders.railway.catenary.parabola_error`) over span lengths, for
sag-to-span ratios from railway wires (0.1 % contact wire pre-sag, 1 % messenger, 2 % feeder)
up to power lines (5 %), and for the railway sag law itself (f_ref 0.5 m at 50 m, alpha 2).
It is set against the thesis scanner's accuracy (2 mm, table 4.3) and the half beam spacing of
its 0.05 deg steps at 10 m (4.4 mm), the error no scan can show. The reference is the analytic
leading-order error s^3 / (3 L^2), checked in the same run.
Run: python benchmarks/bench_railway_catenary.py [--small]
"""

import math
import time

import numpy as np
from common import arguments, report

from bpy_pipeline.builders.railway.catenary import parabola_error, sag_for_span

ACCURACY = 0.002  # m, the thesis scanner's accuracy (table 4.3)
HALF_SPACING_10M = 0.5 * 10.0 * math.radians(0.05)  # m, half the beam spacing of 0.05 deg steps at 10 m


def main():
    args = arguments(__doc__)
    spans = np.geomspace(10, 2000, 12 if args.small else 60)
    ratios = {"contact wire pre-sag 0.1 %": 0.001, "messenger 1 %": 0.01, "feeder 2 %": 0.02, "power line 5 %": 0.05}
    rows, curves = [], {}
    start = time.perf_counter()
    for label, ratio in ratios.items():
        errors = np.array([parabola_error(L, ratio * L) for L in spans])
        curves[label] = errors
        analytic = (ratio * spans) ** 3 / (3 * spans**2)
        worst = float(np.max(np.abs(errors / analytic - 1)))
        # where the parabola's error reaches the scanner's accuracy: s^3 / (3 L^2) = e with s = r L  ->  L = 3 e / r^3
        rows.append({"wire": label, "sag_ratio": ratio, "error_at_50m_m": parabola_error(50.0, ratio * 50.0),
                     "error_at_65m_m": parabola_error(65.0, ratio * 65.0),
                     "span_where_error_reaches_2mm_m": 3 * ACCURACY / ratio**3, "max_rel_dev_from_s3_over_3L2": worst})
    law = np.array([parabola_error(L, sag_for_span(L, 0.5, 50.0, 2.0)) for L in spans])
    curves["messenger, sag law 0.5 m at 50 m, alpha 2"] = law
    rows.append({"wire": "messenger, sag law (alpha 2)", "sag_ratio": None, "error_at_50m_m": parabola_error(50.0, 0.5),
                 "error_at_65m_m": parabola_error(65.0, sag_for_span(65.0, 0.5, 50.0, 2.0)),
                 "span_where_error_reaches_2mm_m": float(np.interp(ACCURACY, law, spans)) if law.max() > ACCURACY else None,
                 "max_rel_dev_from_s3_over_3L2": None})
    elapsed = time.perf_counter() - start

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, errors in curves.items():
        ax.loglog(spans, errors * 1000, label=label)
    ax.axhline(ACCURACY * 1000, color="k", ls="--", lw=1, label="scanner accuracy 2 mm (thesis)")
    ax.axhline(HALF_SPACING_10M * 1000, color="grey", ls=":", lw=1, label="half beam spacing, 0.05 deg at 10 m")
    ax.axvspan(40, 65, color="orange", alpha=0.15, label="railway spans 40-65 m")
    ax.set_xlabel("span length (m)")
    ax.set_ylabel("parabola - catenary, max (mm)")
    ax.set_title("Parabola vs exact catenary, same mid-span sag")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    name = "railway_catenary" + ("_small" if args.small else "")
    args.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out / f"{name}.png", dpi=120)
    report(name, rows, args.out, {"spans_m": [float(spans[0]), float(spans[-1])], "seconds": elapsed, "chart": f"{name}.png"})


if __name__ == "__main__":
    main()
