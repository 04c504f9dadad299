"""Are the realistic renders' detection errors correlated in a way the noise model misses? A
cluster-robust look at sigma_d (issue 12; docs/experiments.md "Correlated errors: a cluster-robust
sigma_d, measured and not adopted").

For each video of bench_linedelay_realistic.py (rendered with --render), the detected corners are
solved whole and in two halves (as the self-check does) with `line_delay_score=True`: each
observation's linearised contribution s_i to d (C++ SchurVariance). For clusters of W consecutive
frames the design effect DE_W = sum_c (sum_{i in c} s_i)^2 / sum_i s_i^2 is the factor by which
errors correlated within W frames inflate var(d) over independent errors (1 for white noise). The
script then replays the self-check and the 3-sigma coverage under candidate sigma_d rules: the
current AR(1) factor (docs/formulation.md §8), sqrt(DE_W), and the larger of the two.

    PYTHONPATH=python .venv/bin/python benchmarks/exp_linedelay_design_effect.py --videos V [--only v00,v07]
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from _common import machine_info, write_results
from exp_linedelay_error_sources import corner_sets

from rscalib.linedelay.selfcheck import AGREE_Z
from rscalib.linedelay.spline import calibrate_line_delay

WINDOWS = (1, 2, 4, 8, 16, 32)


def design_effect(result, window: int) -> float:
    score, obs = result.line_delay_score, result.used_observations
    if len(score) != len(obs.uv) or not np.sum(score ** 2) > 0:
        return math.nan
    cluster = obs.frame_index // window
    totals = np.zeros(cluster.max() + 1)
    np.add.at(totals, cluster, score.sum(axis=1))
    return float(np.sum(totals ** 2) / np.sum(score ** 2))


def solve(obs, camera) -> dict:
    r = calibrate_line_delay(obs, camera, line_delay_score=True)
    return {"d_s": r.line_delay_s, "solver_std_s": r.solver_line_delay_std_s,
            "ar1": r.noise["sigma_d_inflation"], "de": {w: design_effect(r, w) for w in WINDOWS}}


def analyse(folder: Path) -> dict:
    camera, sets, truth, _ = corner_sets(folder)
    obs = sets["detected"]
    t = obs.frame_times_s
    mid = 0.5 * (t[0] + t[-1])
    row = {"name": folder.name, "style": truth["motion_style"], "fps": truth["fps"], "line_delay_s": truth["line_delay_s"],
           "whole": solve(obs, camera), "halves": [solve(obs.subset_frames(keep), camera) for keep in (t < mid, t >= mid)]}
    return row


RULES = {"AR(1) (current)": lambda s: s["ar1"],
         **{f"sqrt(DE_{w})": (lambda s, w=w: math.sqrt(max(1.0, s["de"][w]))) for w in (1, 4, 8)},
         "max(AR(1), sqrt(DE_4))": lambda s: max(s["ar1"], math.sqrt(max(1.0, s["de"][4])))}


def replay(rows: list[dict]) -> str:
    lines = ["| sigma_d rule | within 3σ (after the check) | halves disagree | trusted but outside 3σ | median σ / solver σ |",
             "|---|---:|---:|---:|---:|"]
    for label, factor in RULES.items():
        within = disagree = wrong = 0
        ratios = []
        for r in rows:
            w, (h1, h2) = r["whole"], r["halves"]
            sd = w["solver_std_s"] * factor(w)
            z_halves = abs(h1["d_s"] - h2["d_s"]) / math.hypot(h1["solver_std_s"] * factor(h1),
                                                              h2["solver_std_s"] * factor(h2))
            agree = z_halves <= AGREE_Z
            widened = sd * max(1.0, z_halves)
            err = abs(w["d_s"] - r["line_delay_s"])
            within += err <= 3 * widened
            disagree += not agree
            wrong += agree and err > 3 * widened
            ratios.append(widened / w["solver_std_s"])
        lines.append(f"| {label} | {within}/{len(rows)} | {disagree} | {wrong} | {np.median(ratios):.2f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=Path, required=True)
    parser.add_argument("--only", default="")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "exp_linedelay_design_effect.json")
    args = parser.parse_args()
    names = [n for n in args.only.split(",") if n] or sorted(p.name for p in args.videos.iterdir()
                                                           if p.name.startswith("v") and (p / "truth.json").is_file())
    rows = []
    for name in names:
        row = analyse(args.videos / name)
        rows.append(row)
        w = row["whole"]
        print(f"{name} {row['style']:9s} {row['fps']:4.0f} fps  err {100 * (w['d_s'] / row['line_delay_s'] - 1):+.2f} %  "
              f"AR1 {w['ar1']:.2f}  DE " + " ".join(f"{w['de'][k]:.2f}" for k in WINDOWS)
              + "  halves DE_4 " + " ".join(f"{h['de'][4]:.2f}" for h in row["halves"]), flush=True)
    des = np.array([[r["whole"]["de"][k] for k in WINDOWS] for r in rows])
    table = ("| window W (frames) | " + " | ".join(str(k) for k in WINDOWS) + " |\n|---|" + "---:|" * len(WINDOWS)
             + "\n| median DE_W, whole videos | " + " | ".join(f"{v:.2f}" for v in np.nanmedian(des, axis=0)) + " |\n\n"
             + replay(rows))
    print(table)
    write_results(args.out, "exp_linedelay_design_effect", machine_info(), {"videos": str(args.videos)}, rows, table)


if __name__ == "__main__":
    main()
