"""The report a lab keeps (pipeline.report: model, html; --report on pipeline.run and
pipeline.discover): the figures in the HTML are the summary's, ISO 9283 figures are those of the
recording's repeated poses, nothing is fetched from the network, and headless Chromium renders it
without a console error."""

import json
import re
import shutil
import statistics
import subprocess
from html.parser import HTMLParser

import numpy as np
import pytest

from calib.metrics import iso9283_position, repeated_poses

#: Displayed figures have 4 significant digits: a relative rounding of at most 5e-4.
DISPLAY_RTOL = 5e-4


@pytest.fixture(autouse=True)
def _home(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))  # rerun writes analytics under HOME


class Figures(HTMLParser):
    """The text of every element with a ``data-figure`` attribute, by figure; the src/href values."""

    def __init__(self):
        super().__init__()
        self.figures, self.links, self._open = {}, [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.links += [v for k, v in attrs if k in ("src", "href") and v]
        self._open.append(a.get("data-figure"))
        if a.get("data-figure"):
            self.figures[a["data-figure"]] = ""

    def handle_endtag(self, tag):
        if self._open:
            self._open.pop()

    def handle_data(self, data):
        for f in self._open:
            if f:
                self.figures[f] += data


def figures_of(text: str) -> Figures:
    p = Figures()
    p.feed(text)
    return p


def shown(figs: Figures, key: str, scale: float = 1e3) -> float:
    """A displayed figure back in the summary's unit."""
    return float(figs.figures[key]) / scale


def assert_no_network(text: str, figs: Figures) -> None:
    assert not [u for u in figs.links if re.match(r"\s*(https?:)?//", u)], figs.links
    assert "http://" not in text and "https://" not in text


def chromium_renders(path, tmp_path):
    """Headless Chromium: the screenshot is written, the console has no error, the DOM parses."""
    exe = shutil.which("chromium")
    if exe is None:
        pytest.skip("Debian's chromium package is not installed (apt-get install -y chromium)")
    png = tmp_path / f"{path.stem}.png"
    common = [exe, "--headless", "--disable-gpu", "--no-sandbox", "--enable-logging=stderr", "--v=0"]
    shot = subprocess.run(common + [f"--screenshot={png}", "--window-size=1200,3000", path.resolve().as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert shot.returncode == 0, shot.stderr[-2000:]
    assert png.is_file() and png.stat().st_size > 10_000
    dom = subprocess.run(common + ["--dump-dom", path.resolve().as_uri()], capture_output=True, text=True, timeout=120)
    for log in (shot.stderr, dom.stderr):
        assert "Uncaught" not in log and "ERROR:CONSOLE" not in log, log[-2000:]
    assert 'id="verdict"' in dom.stdout and "<svg" in dom.stdout
    return dom.stdout


# ------------------------------------------------------------------------------------ ISO 9283


def test_iso9283_of_known_points():
    """Independent truth: AP and RP written out from ISO 9283's definitions on hand-made points."""
    rng = np.random.default_rng(1)
    command = np.array([[10.0, 20.0, 30.0], [0.0, 0.0, 0.0]])
    offset = np.array([[0.003, -0.004, 0.0], [0.0, 0.0, 0.012]])
    groups = np.array([0, 1, 0, 1, 0, 1, 0, 2])
    attained = command[np.minimum(groups, 1)] + offset[np.minimum(groups, 1)] + rng.normal(0, 1e-3, (8, 3))
    commanded = command[np.minimum(groups, 1)]
    r = iso9283_position(attained, commanded, groups)
    assert len(r.rows) == 2  # the pose visited once is left out
    for k, g in enumerate((0, 1)):
        pts = attained[groups == g]
        bary = pts.mean(axis=0)
        assert r.accuracy[k] == pytest.approx(np.linalg.norm(bary - command[g]), rel=1e-12)
        dist = [float(np.linalg.norm(p - bary)) for p in pts]
        assert r.repeatability[k] == pytest.approx(statistics.mean(dist) + 3 * statistics.stdev(dist), rel=1e-12)
    # only attained minus commanded enters
    e = iso9283_position(attained - commanded, np.zeros_like(attained), groups)
    np.testing.assert_allclose(e.accuracy, r.accuracy, rtol=1e-12)
    np.testing.assert_allclose(e.repeatability, r.repeatability, rtol=1e-12)


def test_repeated_poses_groups_equal_commands_within_the_joint_noise():
    q = np.array([[1.0, 2.0], [3.0, 4.0], [1.0, 2.0 + 4e-3], [3.0, 4.0], [1.0, 2.1]])
    assert repeated_poses(q).tolist() == [0, 1, 2, 1, 3]
    assert repeated_poses(q, joint_noise_std=1e-3).tolist() == [0, 1, 0, 1, 2]


# ------------------------------------------------------------------------------------- pipeline.run --real


@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    """A simulated hexapod with the reference errors measured like a lab: 40 calibration poses, then
    4 validation poses visited 5 times each in cycles (1 um, 1 urad normal noise); pipeline.run
    --real with --report."""
    from calib.noise import SensorNoise
    from calib.robots import default_robot, reference_errors
    from calib.workspace import reachable_poses
    from pipeline.formats import Recording, write_recording
    from pipeline.run import run
    from pipeline.simulation import Testbed

    out = tmp_path_factory.mktemp("report_run")
    robot = default_robot("hexapod")
    rng = np.random.default_rng(7)
    noise = SensorNoise(0.001, 1e-6, "normal")
    cal = robot.inverse_kinematics(robot.table.nominal, reachable_poses(robot, 40, rng))
    val = robot.inverse_kinematics(robot.table.nominal, reachable_poses(robot, 4, rng))
    joints = np.vstack([cal, np.tile(val, (5, 1))])
    bed = Testbed(robot, robot.table.nominal + reference_errors(robot, 3), noise=noise, seed=5)
    m = bed.measure(joints)
    rec = Recording(robot=robot, noise=noise, t_s=m.t_s, joints=m.encoders, measured=m.measured,
                    sets=np.array(["calibration"] * 40 + ["validation"] * 20))
    write_recording(out / "lab.csv", rec)
    result = run(["--real", str(out / "lab.csv"), "--out", str(out), "--name", "lab_cal", "--quiet",
                  "--report", str(out / "lab.html"), "--summary-json", str(out / "lab.summary.json")])
    return out, rec, result.summary


def test_the_run_report_holds_the_summary_figures(real_run):
    out, _, s = real_run
    text = (out / "lab.html").read_text()
    assert json.loads((out / "lab.summary.json").read_text())["report"] == str(out / "lab.html")
    figs = figures_of(text)
    assert_no_network(text, figs)
    for quantity, key, scale in (("position error", "heldout_position_error_mm", 1e3),
                                 ("orientation error", "heldout_orientation_error_rad", 1e6)):
        for when in ("before", "after"):
            for fig in ("rms", "mean", "max"):
                assert shown(figs, f"heldout/{quantity}/{when}/{fig}", scale) == pytest.approx(
                    s[key][f"{when}_figures"][fig], rel=DISPLAY_RTOL)
    for name in s["free_parameters"]:
        d = s["parameter_determination"][name]
        assert float(figs.figures[f"parameter/{name}/error"]) == pytest.approx(d["error"], rel=DISPLAY_RTOL)
        assert float(figs.figures[f"parameter/{name}/two_sigma"]) == pytest.approx(2 * d["posterior_std"],
                                                                                    rel=DISPLAY_RTOL)
        assert float(figs.figures[f"parameter/{name}/tolerance"]) == pytest.approx(s["prior"]["tolerance"][name],
                                                                                    rel=DISPLAY_RTOL)
    assert figs.figures["flagged"] == (", ".join(map(str, s["flagged_poses"])) or "none")
    assert text.count("<svg") >= 3  # parameters, position and orientation per pose


def test_the_run_reports_iso9283_of_the_repeated_validation_poses(real_run):
    """Independent truth: AP before is the distance from the barycentre of the measured positions
    to where the nominal model puts the command, RP the spread of the measured positions
    (ISO 9283 written out here from the recording); the calibration brings AP down to the noise."""
    from calib.robots import default_robot

    out, rec, s = real_run
    iso = s["iso9283"]["poses"]
    assert len(iso) == 4 and all(p["repeats"] == 5 for p in iso)
    robot = default_robot("hexapod")
    figs = figures_of((out / "lab.html").read_text())
    for k, p in enumerate(iso):
        rows = np.array(p["rows"]) - 1
        assert rec.sets[rows].tolist() == ["validation"] * 5 and np.ptp(rec.joints[rows], axis=0).max() == 0
        measured = rec.measured[rows, :3]
        bary = measured.mean(axis=0)
        command = robot.forward_kinematics(robot.table.nominal, rec.joints[rows[:1]], initial=rec.measured[rows[:1]])
        assert p["AP_before_mm"] == pytest.approx(np.linalg.norm(bary - command[0, :3]), rel=1e-9)
        dist = [float(np.linalg.norm(x - bary)) for x in measured]
        assert p["RP_mm"] == pytest.approx(statistics.mean(dist) + 3 * statistics.stdev(dist), rel=1e-6)
        assert p["AP_after_mm"] < p["AP_before_mm"] / 5
        for fig, key in (("AP_before", "AP_before_mm"), ("AP_after", "AP_after_mm"), ("RP", "RP_mm")):
            assert shown(figs, f"iso9283/{k}/{fig}") == pytest.approx(p[key], rel=DISPLAY_RTOL)


@pytest.mark.slow
def test_the_run_report_opens_in_headless_chromium(real_run, tmp_path):
    out, _, s = real_run
    dom = chromium_renders(out / "lab.html", tmp_path)
    assert "Held-out errors" in dom and "ISO 9283" in dom


def test_an_existing_report_is_not_overwritten(real_run, capsys):
    from pipeline.run import main

    out, _, _ = real_run
    before = (out / "lab.html").read_bytes()
    assert main(["--real", str(out / "lab.csv"), "--out", str(out), "--name", "again", "--quiet",
                 "--report", str(out / "lab.html")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--report" in err[0] and "lab.html" in err[0]
    assert (out / "lab.html").read_bytes() == before


def test_every_string_is_escaped(real_run):
    from dataclasses import replace

    from pipeline.report import REPORT_KEY, Report, render_html

    out, _, _ = real_run
    report = Report.from_dict(json.loads((out / "lab.summary.json").read_text())[REPORT_KEY])
    hostile = replace(report, warnings=('<script>alert("x")</script>',),
                      source=replace(report.source, recording="<img src=x onerror=alert(1)>"))
    text = render_html(hostile)
    assert "<script" not in text and "<img" not in text
    assert "&lt;script&gt;" in text and "&lt;img src=x" in text


# ------------------------------------------------------------------------------------ pipeline.discover


@pytest.fixture(scope="module")
def discovery_run(tmp_path_factory):
    """A hexapod recording with a shared joint friction (a dead band), pipeline.discover --real
    --no-resim --report."""
    from pipeline.discover import run
    from pipeline.formats import write_recording
    from pipeline.simulation import effect_recording

    out = tmp_path_factory.mktemp("report_discover")
    write_recording(out / "fr.csv", effect_recording("joint_friction", 3, n_poses=60))
    report = run(["--real", str(out / "fr.csv"), "--no-resim", "--out", str(out), "--report", str(out / "fr.html")])
    return out, report.summary


@pytest.mark.slow
def test_the_discovery_report_holds_the_effects_and_figures(discovery_run, tmp_path):
    out, s = discovery_run
    text = (out / "fr.html").read_text()
    figs = figures_of(text)
    assert_no_network(text, figs)
    assert s["effects"] == ["joint_friction"] and "joint_friction" in text
    label = "held-out closure residual (geometry alone -> with the effects)"
    assert shown(figs, f"heldout/{label}/before/rms") == pytest.approx(s["heldout_rms_before_mm"], rel=DISPLAY_RTOL)
    assert shown(figs, f"heldout/{label}/after/rms") == pytest.approx(s["heldout_rms_after_mm"], rel=DISPLAY_RTOL)
    assert shown(figs, "heldout/noise floor") == pytest.approx(s["noise_floor_mm"], rel=DISPLAY_RTOL)
    per = s["heldout_per_row"]  # the per-row RMS is the overall RMS taken row by row
    assert np.sqrt(np.mean(np.square(per["before_mm"]))) == pytest.approx(s["heldout_rms_before_mm"], rel=1e-12)
    assert np.sqrt(np.mean(np.square(per["after_mm"]))) == pytest.approx(s["heldout_rms_after_mm"], rel=1e-12)
    for name in s["free_parameters"]:
        assert float(figs.figures[f"parameter/{name}/error"]) == pytest.approx(s["identified_errors"][name],
                                                                               rel=DISPLAY_RTOL)
    comp = s["compensation"]
    assert comp["compensated"] == ["joint_friction"] and len(comp["rows"]) == min(20, len(per["rows"]))
    dead_band = s["effect_parameters"]["joint_friction"]["dead_band"]["value"]
    corrections = np.abs(np.array(comp["rows"])[:, 4:])
    np.testing.assert_allclose(corrections[corrections > 0], dead_band, rtol=1e-6)  # the dead band, moved through
    assert 'id="compensation"' in text
    dom = chromium_renders(out / "fr.html", tmp_path)
    assert "Effects found" in dom and "Compensation" in dom


def test_pipeline_export_to_report_from_the_calibration_file_and_the_summary(real_run, tmp_path, capsys):
    """``pipeline.export --to report``: of the calibration file alone its identified errors and
    their 2 sigma (the file's numbers), said to be the file alone; with the run's ``--summary``
    the same figures as the run's own report; a summary of another robot refused in one line."""
    from pipeline.export import main as export_main
    from pipeline.formats import read_calibration

    out, _, s = real_run
    cal_path = out / "lab_cal.calibration.json"
    cal = read_calibration(cal_path)
    assert export_main(["--calibration", str(cal_path), "--to", "report", "--out", str(tmp_path / "alone.html")]) == 0
    alone = (tmp_path / "alone.html").read_text()
    figs = figures_of(alone)
    assert_no_network(alone, figs)
    assert "from the calibration file alone" in alone
    for name in cal.free:
        k = cal.robot.table.index(name)
        assert float(figs.figures[f"parameter/{name}/error"]) == pytest.approx(
            cal.theta[k] - cal.robot.table.nominal[k], rel=DISPLAY_RTOL)
        assert float(figs.figures[f"parameter/{name}/two_sigma"]) == pytest.approx(2 * cal.std[k], rel=DISPLAY_RTOL)
    assert export_main(["--calibration", str(cal_path), "--to", "report", "--out", str(tmp_path / "run.html"),
                        "--summary", str(out / "lab.summary.json")]) == 0
    with_summary = figures_of((tmp_path / "run.html").read_text())
    assert with_summary.figures == figures_of((out / "lab.html").read_text()).figures
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"robot": "delta"}))
    capsys.readouterr()
    assert export_main(["--calibration", str(cal_path), "--to", "report", "--out", str(tmp_path / "x.html"),
                        "--summary", str(other)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--summary" in err[0] and "hexapod" in err[0]
    assert not (tmp_path / "x.html").exists()
    bare = tmp_path / "bare.json"  # the run's keys without the report they hold
    bare.write_text(json.dumps({k: v for k, v in s.items() if k != "report_model"}))
    assert export_main(["--calibration", str(cal_path), "--to", "report", "--out", str(tmp_path / "x.html"),
                        "--summary", str(bare)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--summary" in err[0] and "report_model" in err[0], err
    assert not (tmp_path / "x.html").exists()
