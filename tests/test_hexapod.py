import numpy as np
import pytest

from calib import paper
from calib.hexapod import (
    ERROR_COLUMNS,
    Hexapod,
    HexapodGeometry,
    paper_geometry,
    paper_hexapod,
    parameter_index,
    parameter_table,
)
from calib.kinematics import inverse_kinematics


def test_builtin_tables_match_reference_transcription(reference_tables):
    t2 = reference_tables["table2_nominal"]
    np.testing.assert_array_equal(paper.TABLE2_BASE_JOINTS_MM, t2["B"])
    np.testing.assert_array_equal(paper.TABLE2_PLATFORM_JOINTS_MM, t2["P"])
    np.testing.assert_array_equal(paper.TABLE2_HOME_LENGTHS_MM, t2["l"])
    t3 = reference_tables["table3_injected_errors"]
    assert tuple(t3["columns"]) == ERROR_COLUMNS
    np.testing.assert_array_equal(paper.TABLE3_ERRORS, t3["rows"])
    t4 = reference_tables["table4_poses"]
    np.testing.assert_array_equal(paper.TABLE4_NOMINAL_POSES, t4["nominal_PT"])
    np.testing.assert_array_equal(paper.TABLE4_MEASURED_POSES, t4["measured_PP"])


def test_home_lengths_are_the_inverse_kinematics_of_the_home_pose():
    g = paper_geometry()
    l = inverse_kinematics(Hexapod(g), g.home_pose[None])[0]
    np.testing.assert_allclose(l, g.home_lengths, atol=1e-5)  # Table 2 prints 8 digits


def test_parameter_table_names_every_parameter_once():
    table = parameter_table()
    assert len(table) == 42
    assert [i for _, i, _ in table] == list(range(42))
    assert {u for *_, u in table} == {"mm"}
    assert table[0][0] == "dXB1" and table[-1][0] == "dZP6"


@pytest.mark.parametrize("name,leg,col", [("dXB3", 3, "dXB"), ("dl5", 5, "dl"), ("dZP6", 6, "dZP"), ("dYB1", 1, "dYB")])
def test_parameter_index_addresses_the_error_array(name, leg, col):
    h = paper_hexapod(with_table3_errors=True)
    assert h.vector[parameter_index(name)] == paper.TABLE3_ERRORS[leg - 1, ERROR_COLUMNS.index(col)]


@pytest.mark.parametrize("name", ["dXB7", "dXB0", "dq1", "XB1", ""])
def test_unknown_parameter_name(name):
    with pytest.raises(KeyError, match="unknown hexapod parameter"):
        parameter_index(name)


def test_errors_apply_to_joints_and_leg_offsets():
    h = paper_hexapod(with_table3_errors=True)
    np.testing.assert_allclose(h.base_joints - paper.TABLE2_BASE_JOINTS_MM, paper.TABLE3_ERRORS[:, :3])
    np.testing.assert_allclose(h.platform_joints - paper.TABLE2_PLATFORM_JOINTS_MM, paper.TABLE3_ERRORS[:, 4:])
    np.testing.assert_allclose(h.leg_offsets, paper.TABLE3_ERRORS[:, 3])
    assert np.all(h.nominal().errors == 0)
    np.testing.assert_array_equal(h.with_errors(h.vector).errors, h.errors)


def test_parameter_sets_are_immutable():
    h = paper_hexapod(with_table3_errors=True)
    with pytest.raises(ValueError):
        h.errors[0, 0] = 1.0
    with pytest.raises(ValueError):
        h.geometry.base_joints[0, 0] = 1.0


@pytest.mark.parametrize("field,value,match", [
    ("base_joints", np.zeros((5, 3)), r"base_joints must have shape \(6, 3\), got \(5, 3\)"),
    ("platform_joints", np.zeros(18), r"platform_joints must have shape \(6, 3\), got \(18,\)"),
    ("home_lengths", np.full(6, np.nan), "home_lengths has a non-finite value"),
])
def test_geometry_validation(field, value, match):
    kw = dict(base_joints=paper.TABLE2_BASE_JOINTS_MM, platform_joints=paper.TABLE2_PLATFORM_JOINTS_MM,
              home_lengths=paper.TABLE2_HOME_LENGTHS_MM)
    kw[field] = value
    with pytest.raises(ValueError, match=match):
        HexapodGeometry(**kw)


def test_errors_validation():
    with pytest.raises(ValueError, match=r"errors must have shape \(6, 7\), got \(7, 6\)"):
        Hexapod(paper_geometry(), np.zeros((7, 6)))


def test_geometry_dict_round_trip():
    g = paper_geometry()
    g2 = HexapodGeometry.from_dict(g.to_dict())
    for f in ("base_joints", "platform_joints", "home_lengths", "home_pose"):
        np.testing.assert_array_equal(getattr(g, f), getattr(g2, f))
