"""The one registry of deliveries (pipeline.deliveries): a delivery registered once is what
``python -m pipeline.export --help`` offers, what the command writes with, and what
``Calibration.deliver`` writes with; a robot it does not accept is refused by both in the same
one line, nothing written; the project's targets are the modules of the package."""

from pathlib import Path

import numpy as np
import pytest

from calib.calibration import Calibration, validity_domain
from calib.robots import ROBOTS, default_robot
from calib.workspace import reachable_poses
from pipeline.deliveries import DELIVERIES, TARGET_MODULES, Delivery, ExportReport, register
from pipeline.export import main as export_main

#: The name of the delivery registered here (no target of the project's).
PLAIN = "plain_text"
#: The robot it accepts.
ACCEPTED = "hexapod"


def write_plain(cal: Calibration, settings) -> ExportReport:
    """A delivery as small as one is: the identified parameters, one per line, at ``settings.out``."""
    text = "".join(f"{n} {v!r}\n" for n, v in zip(cal.robot.table.names, cal.theta))
    out = Path(settings.out)  # the command hands the flag's text, the API a path
    out.write_text(f"{settings.calibration}\n{text}")
    return ExportReport(format=PLAIN, robot=cal.robot.name, paths={out.name: str(out)})


@pytest.fixture
def plain():
    """The delivery ``plain_text``, registered once, for the test only."""
    register(Delivery(name=PLAIN, robots=(ACCEPTED,), write=write_plain))
    yield DELIVERIES[PLAIN]
    del DELIVERIES[PLAIN]


def calibration_file(robot_name: str, folder) -> Calibration:
    """A calibration of the robot (its nominal geometry, one free parameter), written and read back."""
    robot = default_robot(robot_name)
    theta = robot.table.nominal
    poses = reachable_poses(robot, 20, 3, theta=theta)
    cal = Calibration(robot=robot, theta=theta, std=np.zeros(robot.n_parameters), free=robot.table.names[:1],
                      covariance=np.eye(1), validity=validity_domain(robot, poses, robot.inverse_kinematics(theta, poses),
                                                                     [0.0, 1.0]))
    return Calibration.read(cal.write(folder / f"{robot_name}.calibration.json"))


def offered(capsys) -> str:
    """The ``--to`` choices ``python -m pipeline.export --help`` prints."""
    assert export_main(["--help"]) == 0
    return capsys.readouterr().out.split("--to {", 1)[1].split("}", 1)[0]


def test_a_delivery_registered_once_is_offered_by_the_command_and_used_by_both(plain, tmp_path, capsys):
    cal = calibration_file(ACCEPTED, tmp_path)
    assert offered(capsys) == f"linuxcnc,klipper,mjcf,report,{PLAIN}"
    assert export_main(["--calibration", str(cal.source), "--to", PLAIN, "--out", str(tmp_path / "cli.txt")]) == 0
    assert capsys.readouterr().out == f"wrote 1 files of the hexapod's {PLAIN} export: {tmp_path / 'cli.txt'}\n"
    report = cal.deliver(PLAIN, tmp_path / "api.txt")
    assert report.format == PLAIN and report.robot == ACCEPTED
    assert (tmp_path / "api.txt").read_text() == (tmp_path / "cli.txt").read_text()


def test_a_delivery_taken_out_of_the_registry_is_gone_from_both(tmp_path, capsys):
    cal = calibration_file(ACCEPTED, tmp_path)
    register(Delivery(name=PLAIN, robots=(ACCEPTED,), write=write_plain))
    del DELIVERIES[PLAIN]
    assert PLAIN not in offered(capsys).split(",")
    assert export_main(["--calibration", str(cal.source), "--to", PLAIN, "--out", str(tmp_path / "x")]) == 2
    assert f"invalid choice: '{PLAIN}'" in capsys.readouterr().err
    with pytest.raises(ValueError, match=f"no delivery '{PLAIN}' is registered"):
        cal.deliver(PLAIN, tmp_path / "y")
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


@pytest.mark.parametrize("robot", sorted(set(ROBOTS) - {ACCEPTED}))
def test_a_robot_the_delivery_does_not_accept_is_refused_in_one_line_by_both(plain, robot, tmp_path, capsys):
    cal = calibration_file(robot, tmp_path)
    line = f"--to {PLAIN}: it does not deliver the {robot} ({cal.source}); it delivers the {ACCEPTED}"
    assert export_main(["--calibration", str(cal.source), "--to", PLAIN, "--out", str(tmp_path / "cli.txt")]) == 2
    assert capsys.readouterr().err == f"error: {line}\n"
    with pytest.raises(ValueError) as refused:
        cal.deliver(PLAIN, tmp_path / "api.txt")
    assert str(refused.value) == line
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{robot}.calibration.json"]


def test_the_projects_targets_are_the_modules_of_the_package():
    """Each target module holds its DELIVERY, registered under its name, in the order offered."""
    assert [m.DELIVERY.name for m in TARGET_MODULES] == ["linuxcnc", "klipper", "mjcf", "report"]
    assert all(DELIVERIES[m.DELIVERY.name] is m.DELIVERY for m in TARGET_MODULES)
    assert DELIVERIES["linuxcnc"].robots == ("hexapod", "delta")
    assert set(DELIVERIES["mjcf"].robots) == set(DELIVERIES["report"].robots) == set(ROBOTS)


@pytest.mark.parametrize("bad, words", [(dict(name=""), "non-empty string"), (dict(robots=["hexapod"]), "tuple"),
                                        (dict(write=3), "callable")])
def test_a_malformed_delivery_is_refused_by_name(bad, words):
    fields = dict(name="malformed", robots=(ACCEPTED,), write=write_plain) | bad
    with pytest.raises(ValueError, match=words):
        register(Delivery(**fields))
    assert "malformed" not in DELIVERIES and "" not in DELIVERIES
