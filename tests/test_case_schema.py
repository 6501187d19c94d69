"""The case.yaml schema (issue 15 items 1, 2): nonsense numbers, unknown and misplaced keys,
duplicated effects, undecodable files and paths out of the case folder are refused at load time
with a ConfigError naming the file and the field; the docs' table is the schema's."""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest
import yaml

import jflex
from jflex.gap import load_case
from jflex.gap.case._schema import schema_table

DOC = pathlib.Path(__file__).resolve().parent.parent / "docs" / "case_format.md"

# a 2-joint arm as a DH robot YAML (loading checks shapes and names, not physics)
PLANAR2 = dict(
    name="planar2", dh=dict(convention="modified", columns=["alpha", "a", "d", "theta"], angles="deg",
                            rows=[[90, 0.0, 0.3, 0], [0, 0.5, 0.0, 0]], tool=[0, 0.4, 0.0, 0]),
    joint_names=["shoulder", "elbow"], gravity=[0, 0, -9.81],
    links=[dict(mass=6.0, com=[0.25, 0, 0], inertia=[0.02, 0, 0.15, 0, 0, 0.15]),
           dict(mass=3.0, com=[0.2, 0, 0], inertia=[0.01, 0, 0.06, 0, 0, 0.06])])


def write_case(folder: pathlib.Path) -> pathlib.Path:
    """A valid planar2 torque case: robot.yaml, traj0.npz (train), traj1.npz (validation)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robot.yaml").write_text(yaml.safe_dump(PLANAR2))
    rng = np.random.default_rng(0)
    t = np.arange(50) / 100.0
    ds = []
    for i, split in enumerate(("train", "validation")):
        np.savez(folder / f"traj{i}.npz", t=t, q=rng.normal(size=(50, 2)), tau=rng.normal(size=(50, 2)))
        ds.append(dict(kind="torque", file=f"traj{i}.npz", split=split))
    (folder / "case.yaml").write_text(yaml.safe_dump(dict(robot="robot.yaml", nominal_effects=[], datasets=ds),
                                                     sort_keys=False))
    return folder


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    """A valid case, read-only for the tests."""
    return write_case(tmp_path_factory.mktemp("schema") / "ok")


def _case(tmp_path, good, edit=None, name="case"):
    """A copy of ``good`` (case.yaml rewritten by ``edit``, data files linked) in ``tmp_path/name``."""
    folder = tmp_path / name
    folder.mkdir()
    for f in good.iterdir():
        if f.name != "case.yaml":
            (folder / f.name).write_bytes(f.read_bytes())
    cfg = yaml.safe_load((good / "case.yaml").read_text())
    if edit is not None:
        edit(cfg)
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return folder


def _raises(folder, *words, err=jflex.ConfigError, **kw):
    with pytest.raises(err) as e:
        load_case(folder, **kw)
    msg = str(e.value)
    assert "case.yaml" in msg
    for w in words:
        assert w in msg, msg
    return msg


FLEX = {"effect": "joint_flexibility", "joint": "all", "stiffness": [3e5, 2e5], "damping": [10.0, 5.0]}


@pytest.mark.parametrize("edit, words", [
    # a nominal spring of zero stiffness (a divide by zero in the diagnosis before)
    (lambda c: c.update(nominal_effects=[dict(FLEX, stiffness=[3e5, 0])]), ["nominal_effects[0].stiffness", "> 0"]),
    (lambda c: c.update(nominal_effects=[dict(FLEX, damping=-1.0)]), ["nominal_effects[0].damping", ">= 0"]),
    (lambda c: c.update(nominal_effects=[dict(FLEX, stiffness=[3e5, float("nan")])]), ["stiffness", "finite"]),
    (lambda c: c.update(nominal_effects=[dict(FLEX, stiffness=[1e5, 2e5, 3e5])]), ["stiffness", "2 numbers"]),
    (lambda c: c.update(nominal_effects=[dict(FLEX, stiffness="stiff")]), ["stiffness", "'stiff'"]),
    (lambda c: c.update(nominal_effects=[dict(FLEX, stiffness=True)]), ["stiffness", "True"]),
    # a noise floor below zero (reported as -5 before), or not a number (failed after the fit)
    (lambda c: c.update(noise={"modal_frequency_pct": -5}), ["noise.modal_frequency_pct", ">= 0", "-5"]),
    (lambda c: c.update(noise={"modal_frequency_pct": "abc"}), ["noise.modal_frequency_pct", "number", "'abc'"]),
    (lambda c: c.update(noise={"modal_frequency_pct": float("inf")}), ["noise.modal_frequency_pct", "finite"]),
    # unknown keys in noise / options / the top level, named with the allowed ones
    (lambda c: c.update(noise={"torque_pct": 1}), ["noise.torque_pct", "modal_frequency_pct"]),
    (lambda c: c.update(options={"max_effect": 2}), ["options.max_effect", "max_effects"]),
    (lambda c: c.update(robots="x"), ["'robots'", "robot"]),
    # a coefficient on an effect that takes none
    (lambda c: c.update(nominal_effects=[{"effect": "viscous_friction", "stiffness": 3.0}]),
     ["nominal_effects[0].stiffness", "'viscous_friction'", "['effect', 'joint']"]),
    (lambda c: c.update(nominal_effects=[{"effect": "joint_flexibility", "value": 3.0}]),
     ["nominal_effects[0].value", "stiffness", "damping"]),
    # the same effect twice at a joint ('all' overlaps a name)
    (lambda c: c.update(nominal_effects=[{"effect": "viscous_friction"}, {"effect": "viscous_friction", "joint": "elbow"}]),
     ["nominal_effects[1].joint", "'elbow'", "nominal_effects[0]"]),
    (lambda c: c.update(nominal_effects=[{"effect": "coulomb_friction", "joint": [0, "shoulder"]}]),
     ["nominal_effects[0].joint", "shoulder"]),
    # a joint that is no joint (a TypeError before)
    (lambda c: c.update(nominal_effects=[{"effect": "payload", "joint": 1.5}]), ["nominal_effects[0].joint", "1.5"]),
    (lambda c: c.update(nominal_effects=[{"effect": "payload", "joint": 7}]), ["nominal_effects[0].joint", "out of range"]),
    (lambda c: c.update(nominal_effects=[{"effect": "payload", "joint": ["all", "elbow"]}]), ["nominal_effects[0].joint", "'all'"]),
    # options: ranges and types
    (lambda c: c.update(options={"decimate": 0}), ["options.decimate", ">= 1"]),
    (lambda c: c.update(options={"decimate": 2.5}), ["options.decimate", "integer"]),
    (lambda c: c.update(options={"filter_cutoff_hz": -3}), ["options.filter_cutoff_hz", "> 0"]),
    (lambda c: c.update(options={"filter_cutoff_hz": "fast"}), ["options.filter_cutoff_hz", "'fast'"]),
    (lambda c: c.update(options={"refit_inertia": "yes"}), ["options.refit_inertia", "true or false"]),
    (lambda c: c.update(options={"inertia_prior": -1}), ["options.inertia_prior", ">= 0"]),
    (lambda c: c.update(options={"max_effects": -1}), ["options.max_effects", ">= 0"]),
    # data set entries
    (lambda c: c["datasets"][1].update(split="test"), ["datasets[1].split", "['train', 'validation']", "'test'"]),
    (lambda c: c["datasets"][0].update(file=3), ["datasets[0].file", "string"]),
    (lambda c: c["datasets"][0].update(file="traj0.mat"), ["datasets[0].file", ".npz"]),
    (lambda c: c["datasets"][0].update(q0=[0.1, 0.2]), ["datasets[0].q0", "NPZ"]),
    (lambda c: c["datasets"][0].update(scale={"a": 1.0}), ["datasets[0].scale", "CSV"]),
    (lambda c: c["datasets"].append("traj0.npz"), ["datasets[2]", "mapping"]),
    (lambda c: c.update(datasets=[]), ["datasets", "at least 1"]),
])
def test_schema_refuses_with_field(tmp_path, good, edit, words):
    _raises(_case(tmp_path, good, edit), *words)


def test_valid_case_options_and_noise(tmp_path, good):
    c = load_case(good)
    # options come with their defaults (the diagnosis reads them); noise holds only what is stated
    assert c.options == {"inertia_prior": 1.0, "refit_inertia": True, "filter_cutoff_hz": "auto", "decimate": 1,
                         "max_effects": 3, "keep_channels": [], "replace_spikes": False}
    assert c.noise == {}
    folder = _case(tmp_path, good, lambda c: c.update(
        options={"filter_cutoff_hz": 12, "decimate": 2, "refit_inertia": False}, noise={"modal_frequency_pct": 2},
        nominal_effects=[dict(FLEX, stiffness=4e5), {"effect": "rotor_inertia", "joint": [1], "value": 0.02},
                         {"effect": "viscous_friction", "joint": None}]))
    c = load_case(folder)
    assert c.options["filter_cutoff_hz"] == 12.0 and c.options["decimate"] == 2 and c.options["refit_inertia"] is False
    assert c.noise == {"modal_frequency_pct": 2.0}
    flex, rotor, visc = c.nominal_effects
    np.testing.assert_array_equal(flex["stiffness"], [4e5, 4e5])  # one number for every joint
    assert rotor["joints"] == ("elbow",) and visc["joints"] == ("shoulder", "elbow")


def test_empty_blocks_read_as_defaults(tmp_path, good):
    folder = _case(tmp_path, good)
    text = (folder / "case.yaml").read_text()
    (folder / "case.yaml").write_text(re.sub(r"nominal_effects: \[\]\n", "nominal_effects:\nnoise:\noptions:\n", text))
    assert load_case(folder).nominal_effects == []


def test_undecodable_case_yaml(tmp_path, good):
    folder = _case(tmp_path, good)
    (folder / "case.yaml").write_bytes(b"robot: robot.yaml\nnotes: caf\xe9 \xff\n")
    _raises(folder, "UTF-8")


def test_seed_configs_load():
    for folder in sorted((DOC.parent.parent / "configs" / "cases").iterdir()):
        c = load_case(folder)
        assert c.nominal_effects[0]["effect"] == "joint_flexibility" and c.noise == {"modal_frequency_pct": 1.0}


# --- paths stay inside the case folder -------------------------------------------------------------
def test_paths_outside_the_case_are_refused(tmp_path, good):
    other = _case(tmp_path, good, name="other")
    outside = [
        ("datasets[0].file", lambda c: c["datasets"][0].update(file="../other/traj0.npz")),
        ("datasets[1].file", lambda c: c["datasets"][1].update(file=str(other / "traj1.npz"))),
        ("datasets[0].file", lambda c: c["datasets"][0].update(file="../../../../../../etc/passwd.npz")),
        ("robot", lambda c: c.update(robot="../other/robot.yaml")),
        ("robot", lambda c: c.update(robot="../other/robot")),
        ("robot_inertia", lambda c: c.update(robot_inertia="/etc/inertia.npz")),
    ]
    for k, (field, edit) in enumerate(outside):
        folder = _case(tmp_path, good, edit, name=f"c{k}")
        msg = _raises(folder, f"'{field}'")
        assert "outside" in msg or "absolute" in msg or "config name" in msg
    # the user's explicit flag lets the first two load (the same data as the case's own files)
    for k in (0, 1):
        c = load_case(tmp_path / f"c{k}", allow_outside=True)
        np.testing.assert_array_equal(c.datasets[k].arrays["tau"], load_case(good).datasets[k].arrays["tau"])
    # '..' that stays inside is fine
    folder = _case(tmp_path, good, lambda c: c["datasets"][0].update(file="sub/../traj0.npz"), name="inside")
    (folder / "sub").mkdir()
    load_case(folder)


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symbolic links")
def test_symlink_out_of_the_case_is_refused(tmp_path, good):
    other = _case(tmp_path, good, name="other")
    folder = _case(tmp_path, good, lambda c: c["datasets"][0].update(file="link.npz"))
    (folder / "link.npz").symlink_to(other / "traj0.npz")
    _raises(folder, "'datasets[0].file'", "outside")
    (folder / "inner.npz").symlink_to(folder / "traj0.npz")  # a link within the folder is fine
    _edit = yaml.safe_load((folder / "case.yaml").read_text())
    _edit["datasets"][0]["file"] = "inner.npz"
    (folder / "case.yaml").write_text(yaml.safe_dump(_edit))
    load_case(folder)


def test_path_check_does_not_open_the_file(tmp_path, good, monkeypatch):
    folder = _case(tmp_path, good, lambda c: c["datasets"][0].update(file="../secret.npz"))
    opened = []
    monkeypatch.setattr(np, "load", lambda *a, **k: opened.append(a) or pytest.fail("opened"))
    _raises(folder, "'datasets[0].file'")
    assert opened == []


def test_cli_allow_outside(tmp_path, good):
    folder = _case(tmp_path, good, lambda c: c["datasets"][0].update(file="../other/traj0.npz"))
    r = subprocess.run([sys.executable, "-m", "jflex.cli", "diagnose", str(folder), "--out", str(tmp_path / "run")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "datasets[0].file" in r.stderr and "--allow-outside" in r.stderr


# --- the docs' table is the schema's -------------------------------------------------------------
def test_doc_table_is_the_schema():
    text = DOC.read_text()
    m = re.search(r"<!-- schema-table -->\n(.*?)\n<!-- /schema-table -->", text, re.S)
    assert m, "docs/case_format.md lacks the <!-- schema-table --> block"
    assert m.group(1).strip() == schema_table().strip(), "regenerate: python -m jflex.gap.case._schema"


# --- experiment configs: the same hook ------------------------------------------------------------
def test_experiment_config_schema(tmp_path):
    sys.path.insert(0, str(DOC.parent.parent / "experiments"))
    try:
        import posture_modal
    finally:
        sys.path.pop(0)
    shipped = DOC.parent.parent / "configs" / "posture_modal.yaml"
    seen = []

    def run(cfg, run_dir):
        seen.append(cfg)
        return {}

    jflex.experiment_cli("pm", shipped, run, ["--out", str(tmp_path / "ok")], schema=posture_modal.PostureModalConfig)
    assert seen[0]["tool_frame"] == "tool" and seen[0]["map"]["chunk_size"] == 1024 and seen[0]["frf"]["n"] == 600
    for edit, field in [(lambda c: c["frf"].update(f_max_Hz=0.5), "frf"),
                        (lambda c: c["map"].update(n_q2="41"), "map.n_q2"),
                        (lambda c: c["lobes"].update(cutting_axes=[[0, 1, 0]]), "lobes.cutting_axes"),
                        (lambda c: c.update(robot="x"), "robot")]:
        bad = yaml.safe_load(shipped.read_text())
        edit(bad)
        path = tmp_path / "bad.yaml"
        path.write_text(yaml.safe_dump(bad))
        with pytest.raises(jflex.ConfigError, match=rf"bad\.yaml: field '{re.escape(field)}'"):
            jflex.experiment_cli("pm", path, run, ["--out", str(tmp_path / "bad")], schema=posture_modal.PostureModalConfig)
    assert len(seen) == 1  # run never saw a bad config
