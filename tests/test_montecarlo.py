"""fcrlive montecarlo: figures of merit (eqs. 35-36, coverage) on synthetic numbers, failure recording,
and a tiny study end to end (in process and with two worker processes, resume, CLI)."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from fcrlive.analysis import montecarlo as mc
from fcrlive.errors import UserError
from fcrlive.plant.params import preset

PLANT = preset("paper-plant1")


# --- figures of merit -------------------------------------------------------------------------------


def test_nrmse_is_eq35():
    a0 = 0.0794
    est = [0.08, 0.07, 0.1, 0.0794, float("nan")]
    # eq. 35 written out by hand over the four finite estimates
    want = math.sqrt(((a0 - 0.08) ** 2 + (a0 - 0.07) ** 2 + (a0 - 0.1) ** 2 + 0.0) / 4)
    assert mc.nrmse(est, a0) == pytest.approx(want, rel=1e-12)
    assert math.isnan(mc.nrmse([float("nan")], a0))


def test_nrmse_omega_is_eq36_on_complex_values():
    G = np.array([2 - 4j, 1 + 0.5j])
    est = np.array([[2 - 4j, 1.5 + 0.5j], [3 - 4j, 1 + 1.5j], [2 - 3j, 1 + 0.5j]])
    want0 = math.sqrt((0 + 1 + 1) / 3 / abs(G[0]) ** 2)
    want1 = math.sqrt((0.25 + 1 + 0) / 3 / abs(G[1]) ** 2)
    got = mc.nrmse_omega(est, G)
    assert got == pytest.approx([want0, want1], rel=1e-12)
    # phase errors count (complex difference), not only magnitude errors
    rot = mc.nrmse_omega(G[None, :] * np.exp(0.1j), G)
    assert rot == pytest.approx(2 * math.sin(0.05) * np.ones(2), rel=1e-9)


def test_coverage_counts_intervals_containing_the_truth():
    lo = [0.9, 1.1, 0.5, np.nan, 0.0, 1.0]
    hi = [1.2, 1.3, 0.99, 2.0, 1.0, 1.0]
    # truth 1.0: in [0.9,1.2], not [1.1,1.3], not [0.5,0.99], skip NaN, in [0,1] (edge), in [1,1]
    assert mc.coverage(lo, hi, 1.0) == pytest.approx(3 / 5)
    assert math.isnan(mc.coverage([np.nan], [np.nan], 1.0))


def test_summarise_cell_on_synthetic_rows():
    tr = mc.truth(PLANT, periods_s=(100.0, 10.0))
    rows = []
    for i, (g, lo, hi) in enumerate([(0.08, 0.07, 0.09), (0.075, 0.08, 0.09), (0.09, 0.06, 0.1)]):
        r = {"snr_db": 12.0, "minutes": 10.0, "method": "zcu", "run": i, "status": "ok", "reason": "",
             "g1_static": g, "g1_static_lo": lo, "g1_static_hi": hi}
        for T, gp in zip(tr.periods_s, tr.gp * (1 + 0.1 * i)):
            t = f"T{T:g}"
            r.update({f"gp_re_{t}": gp.real, f"gp_im_{t}": gp.imag, f"gp_lo_{t}": abs(gp) * 0.95,
                      f"gp_hi_{t}": abs(gp) * 1.05})
        rows.append(r)
    rows.append({"snr_db": 12.0, "minutes": 10.0, "method": "zcu", "run": 3, "status": "failed",
                 "reason": "DataError: boom"})
    s = mc.summarise_cell(rows, tr)
    assert (s["runs"], s["ok"], s["failed"]) == (4, 3, 1)
    assert s["failure_reasons"] == {"DataError: boom": 1}
    g = s["g1_static"]
    a0 = tr.g1_static
    want = math.sqrt(((0.08 - a0) ** 2 + (0.075 - a0) ** 2 + (0.09 - a0) ** 2) / 3)
    assert g["nrmse"] == pytest.approx(want)
    assert g["bias"] == pytest.approx((0.08 + 0.075 + 0.09) / 3 - a0)
    assert g["rel_nrmse"] == pytest.approx(g["nrmse"] / a0)
    assert g["coverage"] == pytest.approx(2 / 3)  # the second interval misses 0.0794
    # G_p scaled by 1, 1.1, 1.2: relative complex error 0, 0.1, 0.2 at every period
    assert s["gp"]["nrmse"] == pytest.approx([math.sqrt((0.01 + 0.04) / 3)] * 2, rel=1e-9)
    assert s["gp"]["coverage"] == pytest.approx([1 / 3] * 2)
    assert "max_s" not in s


def test_truth_matches_the_paper():
    tr = mc.truth(PLANT)
    assert tr.g1_static == pytest.approx(0.0794, abs=5e-5)
    assert tr.max_g1 == pytest.approx(1.01, abs=0.005)
    assert tr.max_s == pytest.approx(1.29, abs=0.005)
    assert len(tr.gp) == 11


def test_sine_layout_fits_the_dataset():
    n, k, m = mc.sine_layout(PLANT, 300.0, 600.0)
    assert (k, m) == (1, 1) and n == round(600 / PLANT.unit.governor.Tc)
    n, k, m = mc.sine_layout(PLANT, 10.0, 1800.0)
    assert k * 10.0 >= 500.0 and k + m == 180  # 5 slowest time constants settle when there is room
    with pytest.raises(UserError):
        mc.sine_layout(PLANT, 300.0, 500.0)


def test_seeds_differ_per_run_and_period():
    seeds = {mc.run_seed(0, i) for i in range(50)}
    seeds |= {mc.sine_seed(0, i, k) for i in range(50) for k in range(11)}
    assert len(seeds) == 50 + 550
    assert mc.run_seed(0, 3) == mc.run_seed(0, 3) != mc.run_seed(1, 3)


# --- failures ---------------------------------------------------------------------------------------


def test_failed_identification_is_recorded_not_raised():
    # 10 min: on 6 min at 12 dB Z_cu's swing pole (hence G_1(0)) is not determined by the data (sd of
    # G_1(0) above 1); which wrong value came out then depended on the BLAS kernel
    cfg = mc.StudyConfig(runs=2, snr_db=(12.0,), minutes=(10.0,), methods=("zcu",), model="linear",
                         periods_s=(100.0, 25.0))
    task = mc.plan(cfg, mc.process_noise_levels(PLANT, cfg))[0]
    real = mc._identify_closed_loop(PLANT, cfg)

    def identify(method, sig):
        if f"seed {mc.run_seed(cfg.seed, 1)}" in sig.sources[0]:
            raise np.linalg.LinAlgError("singular matrix in run 1")
        return real(method, sig)

    res = mc.run_task(PLANT, cfg, task, identify=identify)
    by_run = {r["run"]: r for r in res.rows}
    assert by_run[0]["status"] == "ok" and by_run[0]["g1_static"] == pytest.approx(0.0794, rel=0.3)
    assert by_run[1]["status"] == "failed"
    assert by_run[1]["reason"] == "LinAlgError: singular matrix in run 1"
    assert np.all(np.isnan(res.grids["zcu/G_1"][1])) and np.all(np.isfinite(res.grids["zcu/G_1"][0]))


def test_sine_period_too_long_for_the_dataset_is_a_failure():
    cfg = mc.StudyConfig(runs=1, snr_db=(12.0,), minutes=(3.0,), methods=("sine",), model="linear",
                         periods_s=(150.0, 25.0))
    task = mc.plan(cfg, mc.process_noise_levels(PLANT, cfg))[0]
    (row,) = mc.run_task(PLANT, cfg, task).rows
    assert row["status"] == "failed" and "T=150 s" in row["reason"]


# --- end to end ------------------------------------------------------------------------------------


def _tiny(**kw):
    base = dict(runs=3, snr_db=(12.0,), minutes=(6.0,), methods=("zcu", "sine"), model="linear",
                periods_s=(120.0, 60.0, 20.0), chunk=2)
    base.update(kw)
    return mc.StudyConfig(**base)


@pytest.mark.parametrize("workers", [1, 2])
def test_tiny_study_end_to_end(tmp_path, workers):
    cfg = _tiny()
    res = mc.run_study(PLANT, cfg, tmp_path, workers=workers, progress=False)
    assert res.timing["tasks_run"] == 4  # (excited, sine) × 2 chunks
    with open(tmp_path / "runs.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and {r["method"] for r in rows} == {"zcu", "sine"}
    assert all(r["status"] == "ok" for r in rows), [r["reason"] for r in rows]
    summary = json.loads((tmp_path / "summary.json").read_text())
    cells = {c["method"]: c for c in summary["cells"]}
    assert cells["zcu"]["ok"] == 3 and 0 <= cells["zcu"]["g1_static"]["coverage"] <= 1
    # the sine test measures G_req ≈ G_p closely at 12 dB with a 0.1 Hz sine
    assert max(cells["sine"]["gp"]["nrmse_vs_greq"]) < 0.1
    assert "max_g1" not in cells["sine"] and len(cells["zcu"]["gp"]["nrmse"]) == 3
    for name in ("fig7a_nrmse_g1_static.png", "fig8_nrmse_max_s.png", "fig9_nrmse_gp_6min.png",
                 "fig4-6_mean_responses.png"):
        assert (tmp_path / name).stat().st_size > 5000
    md = (tmp_path / "summary.md").read_text()
    assert "| 12 dB | 6 min | Z_cu | 3/3 |" in md and "sine vs G_req" in md
    if workers == 2:
        # resume: everything is done, nothing is recomputed, the same rows come back
        again = mc.run_study(PLANT, cfg, tmp_path, workers=2, progress=False, figures=False)
        assert again.timing["tasks_run"] == 0
        assert [r["g1_static"] for r in again.rows if r["method"] == "zcu"] == pytest.approx(
            [r["g1_static"] for r in res.rows if r["method"] == "zcu"])
        with pytest.raises(UserError, match="different study"):
            mc.run_study(PLANT, _tiny(seed=7), tmp_path, workers=1, progress=False)


def test_cli_tiny_study(tmp_path, capsys):
    from fcrlive.cli import main

    rc = main(["montecarlo", "--runs", "2", "--snr-db", "6", "--minutes", "6", "--methods", "zu", "--model",
               "linear", "--workers", "1", "--no-progress", "--no-figures", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 0
    assert "| 6 dB | 6 min | Z_u | " in out and "identification zu/6min" in out
    assert (tmp_path / "runs.csv").exists() and not (tmp_path / "fig8_nrmse_max_s.png").exists()
    assert main(["montecarlo", "--runs", "0", "--out", str(tmp_path)]) == 2
