"""report.html of the demo diagnosis: written beside report.md, self-contained (figures embedded,
nothing from the network), one image per promised figure, the named sections, nominal effects
marked, and the payload as a mass and a centre of mass in the tool frame, checked against the
demo case's hidden truth."""

import base64
import html
import json
import pathlib
import re

import numpy as np
import pytest

import jflex
from jflex.gap import demo
from jflex.gap._demo import DATA


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    demo(out, progress=False)
    return out


@pytest.fixture(scope="module")
def page(run):
    return (run / "report.html").read_text()


def test_report_html_beside_report_md_and_self_contained(run, page):
    assert (run / "report.md").is_file()
    assert "report.html" in (run / "report.md").read_text()
    # nothing fetched: no http(s) or protocol-relative address in any src or href, no scripts
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", page, re.I)
    assert "<script" not in page.lower() and "@import" not in page


def test_one_embedded_image_per_promised_figure(run, page):
    imgs = re.findall(r"<img\b[^>]*>", page)
    alts = [re.search(r'alt="([^"]+)"', i).group(1) for i in imgs]
    assert len(alts) == len(set(alts))
    # promised: measured vs nominal vs final for every validation set of case.yaml, the waterfall,
    # and every other plot the run wrote
    case = jflex.load_yaml(run / "case" / "case.yaml")
    promised = {"waterfall.png"}
    for d in case["datasets"]:
        if d["split"] == "validation" and d["kind"] in ("torque", "frf"):
            promised.add(f"{d['kind']}_{d.get('name') or pathlib.Path(d['file']).stem}.png")
    written = {p.name for p in run.glob("*.png")}
    assert promised <= written
    assert set(alts) == written
    for tag, alt in zip(imgs, alts):  # the embedded bytes are the PNG the run wrote
        data = re.search(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', tag).group(1)
        assert base64.b64decode(data) == (run / alt).read_bytes()
    # each figure explained once: one caption per image
    assert len(re.findall(r"<figcaption>", page)) == len(imgs)


def test_named_sections_and_terms(run, page):
    for key in ("summary", "selected", "model", "datasets", "waterfall", "where", "ranking", "terms"):
        assert re.search(rf"<h2 id='{key}'>", page), key
    robot = jflex.load_yaml(run / "case" / "robot.yaml")["name"]
    assert f"<h1>Gap diagnosis of {robot}</h1>" in page
    for term in ("<dt>score</dt>", "<dt>signature</dt>", "<dt>noise floor</dt>", "<dt>shrink</dt>"):
        assert term in page
    diag = json.loads((run / "diagnosis.json").read_text())
    assert diag["verdict"].replace("_", " ") in page and diag["stop_reason"] in page
    # every selected effect comes with a reason; the case's nominal effects are marked nominal
    assert page.count("It closed ") == len(diag["selected"])
    nominal = jflex.load_yaml(run / "case" / "case.yaml")["nominal_effects"]
    for n in nominal:
        assert re.search(rf"{n['effect']}@\w+ <span class='tag nominal'>nominal</span>", page)


def test_payload_line_gives_mass_in_kg_and_com_in_tool_frame(page):
    m = re.search(r"[Pp]ayload (\d+\.\d+) kg, centre of mass at \(([-\d.]+), ([-\d.]+), ([-\d.]+)\) mm in the "
                  r"tool frame", page)
    assert m is not None
    truth = next(e for e in json.loads((DATA / "demo_truth.json").read_text())["effects"] if e["effect"] == "payload")
    # the generator placed the payload at the tool frame's origin plus 'offset' (tool axes = link axes here)
    assert abs(float(m.group(1)) / truth["params"]["m"] - 1) < 0.05
    com_mm = np.array([float(m.group(k)) for k in (2, 3, 4)])
    assert np.max(np.abs(com_mm - 1e3 * np.asarray(truth["params"]["offset"]))) < 5.0


def _rewritten(run, **changes):
    """The demo's diagnosis.json with ``changes``, rendered again as report.md and report.html."""
    from jflex.gap.report import _html
    from jflex.gap.report import _report

    r = json.loads((run / "diagnosis.json").read_text())
    r.update(changes)
    payload = changes.pop("_payload", None)
    r.pop("_payload", None)
    md = _report.markdown(r, [], robot="arm", payload=payload)
    page = _html.page(r, run, [], robot_name="arm", nominal_effects=[], payload=payload, modal_tables={}, set_gaps={})
    return md, page


def test_report_speaks_words_and_names_what_it_means(run):
    diag = json.loads((run / "diagnosis.json").read_text())
    md = (run / "report.md").read_text()
    assert "**True**" not in md and "**False**" not in md
    assert ("significant (above the noise floor)" if diag["significant"] else "not significant") in md
    # the floor's method and interval, per validation set, in both reports
    for k, d in diag["noise_floor_details"].items():
        assert d["method"] in md and not d["failed"]
        # the black box's per-channel models name their channels as the rest of the file does
        for key in ("base_only", "angle_series", "rigid_body", "history", "unpredicted"):
            assert all(isinstance(c, str) for c in d.get(key, [])), (key, d.get(key))
    # an effect of no joint in an ambiguous pair: no literal "(None)"
    md, page = _rewritten(run, ambiguous=[dict(effects=["sensor_delay", "viscous_friction"], joints=[None, "j2"],
                                               known_pair=True, shrink=[60.0, 58.0])])
    assert "(None)" not in md and "(None)" not in page and "sensor_delay vs viscous_friction at j2" in md


def test_tolerance_bound_names_the_parameter(run):
    move = dict(link="link3", mass_cad_kg=1.0, mass_kg=1.0, mass_change_pct=0.0, com_cad_m=[0, 0, 0], com_m=[0, 0, 0],
                com_shift_m=0.0, at_tolerance_bound=True, bound_parameters=["Izz +0.02 kg m^2"])
    md, page = _rewritten(run, inertia_refit=[move])
    assert "yes: Izz +0.02 kg m^2" in md and "yes: Izz +0.02 kg m^2" in page


def test_a_non_physical_payload_is_said_so():
    from jflex.gap.report._html import payload_line, payload_summary

    class Robot:
        nq, link_names = 2, ("a", "b")

    p = {"m [kg]": 0.0, "m cx [kg m]": 0.0, "m cy [kg m]": 0.0, "m cz [kg m]": 0.0, "Ixx [kg m^2]": -3.5,
         "Ixy [kg m^2]": 0.0, "Iyy [kg m^2]": 0.1, "Ixz [kg m^2]": 0.0, "Iyz [kg m^2]": 0.0, "Izz [kg m^2]": 0.1}
    pl = payload_summary({"torque": {"payload": p}}, Robot(), None)
    assert "non-physical" in payload_line(pl) and "0.000 kg" not in payload_line(pl)
    p.update({"m [kg]": 1.0, "m cz [kg m]": 0.1})
    assert "non-physical" in payload_line(payload_summary({"torque": {"payload": p}}, Robot(), None))  # Ixx < 0
    p["Ixx [kg m^2]"] = 0.1 + 1.0 * 0.1**2
    pl = payload_summary({"torque": {"payload": p}}, Robot(), None)
    assert "non-physical" not in payload_line(pl) and "1.000 kg" in payload_line(pl)


def test_data_section_lists_left_out_channels_and_conditioning(run):
    md, page = _rewritten(run, excluded_channels={"val": {"j3": "no signal: the torque is constant (0.013 N m throughout)"}},
                          conditioning={"val": {"sampling": "resampled 2 % jittered stamps"}})
    for text in (md, page):
        assert "j3 (no signal: the torque is constant (0.013 N m throughout))" in text
        assert "resampled 2 % jittered stamps" in text


def test_conditioning_is_a_table_of_what_the_data_layer_found_and_did(run):
    """A record conditioned by the data layer (stamps jittering by 20 % with 3 samples dropped,
    one dead torque channel, a constant one kept by the user, a spike) reads as one table row per record in
    both reports: the numbers the stamps gave, the channels' flags and what was done with them,
    the low-pass cutoff of that record; no Python dict is printed."""
    from jflex.data._condition import condition_torque

    rng = np.random.default_rng(3)
    h = 0.002
    steps = h * (1 + 0.2 * rng.uniform(-1, 1, 1999))
    steps[500] += 3 * h  # three samples lost
    t = np.concatenate([[0.0], np.cumsum(steps)])
    q = np.sin(np.outer(t, [1.0, 2.0, 3.0]))
    tau = np.column_stack([np.cos(2 * t), np.zeros_like(t), 0.01 * rng.normal(size=t.size)])
    tau[:, 1][t > 3.5] = 0.2 * np.sin(t[t > 3.5])  # dead 85 % of the time
    tau[700, 0] += 50.0
    tau[:, 2] = 0.004  # constant
    _, _, rep, excluded = condition_torque(t, dict(q=q, tau=tau), ("a", "b", "c"), "rec", keep=("c",))
    assert excluded == ("b",)
    proc = {"val": {"cutoff_hz": 12.5, "cutoff_method": "motion_band", "derivatives": "angles filtered, then differentiated twice"}}
    rep["window_s"] = [12.5, None]  # the held-out end of a run: to the end of the record
    md, page = _rewritten(run, conditioning={"val": rep}, processing=proc)
    for text in (md, page):
        assert "{'" not in text.split("conditioning")[1][:3000]  # no dict printed
        assert re.search(r"jitter 2\d %, 3 dropped", text), text[:200]
        assert "resampled (" in text
        assert "b: dead (left out)" in text and "c: flat, few levels (kept by the user)" in text
        assert re.search(r"a: [12] \(flagged\)", text)  # one sample, two once resampled
        assert "12.5 (motion band)" in text
        assert "'val' cut to the window from 12.5 s to the end of the record." in html.unescape(text)


def test_payload_shown_once_with_units_in_markdown(run):
    md = (run / "report.md").read_text()
    assert "m cx [kg m]" not in md  # the link-frame first moments are not a second payload
    assert re.search(r"Payload: payload \d+\.\d+ kg, centre of mass at", md)
