"""The report links every figure written beside it (the demo's rigid maps too), says how an
effect can be both confounded with the inertia refit and selected, and gives a prismatic joint's
effect parameters in N (per m), not N m (per rad)."""

from __future__ import annotations

from jflex.gap.report._report import add_figures, markdown, prismatic_units


def _png(path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1, 1))
    ax.plot([0, 1])
    fig.savefig(path)
    plt.close(fig)


def test_figures_written_after_the_report_are_linked(tmp_path):
    (tmp_path / "report.md").write_text("# Gap diagnosis\n")
    (tmp_path / "report.html").write_text("<html><body><h1>x</h1></body></html>")
    (tmp_path / "rigid_maps").mkdir()
    for f in ("gravity_maps.png", "workspace.png"):
        _png(tmp_path / "rigid_maps" / f)
    add_figures(tmp_path, [("rigid_maps/gravity_maps.png", "gravity"), ("rigid_maps/workspace.png", "tool")], "Maps")
    md = (tmp_path / "report.md").read_text()
    assert "](rigid_maps/gravity_maps.png)" in md and "](rigid_maps/workspace.png)" in md
    page = (tmp_path / "report.html").read_text()
    assert page.count("data:image/png;base64,") == 2 and page.rstrip().endswith("</body></html>")
    assert page.index("rigid_maps/workspace.png") < page.index("</body>")


def test_prismatic_joint_parameters_in_newtons():
    p = {"torque": {"coulomb_friction@slide": {"Fc [N m]": 2.0}, "viscous_friction@slide": {"Fv [N m s/rad]": 1.0},
                    "torque_offset@slide": {"offset [N m]": 0.5}, "torque_offset@elbow": {"offset [N m]": 0.3},
                    "rotor_inertia@slide": {"Im [kg m^2]": 0.1}}}
    got = prismatic_units(p, {"slide"})["torque"]
    assert got["coulomb_friction@slide"] == {"Fc [N]": 2.0}
    assert got["viscous_friction@slide"] == {"Fv [N s/m]": 1.0}
    assert got["torque_offset@slide"] == {"offset [N]": 0.5}
    assert got["rotor_inertia@slide"] == {"Im [kg]": 0.1}
    assert got["torque_offset@elbow"] == {"offset [N m]": 0.3}  # a revolute joint keeps N m


def _result(**kw):
    step = dict(effect="payload", joint=None, gap_after=2.0, shrink=80.0, score=300.0, signature=None)
    r = dict(case="c", gap_before=10.0, gap_after=2.0, noise_floor=1.0, significant=True, shrink=80.0,
             remaining_significant=False, selected=[step], confounded_with_inertia_refit=[
                 dict(effect="payload", joint=None, relative_residual=1e-3)], ambiguous=[], ranking=[step], where=[],
             unmatched_modes=[], steps=[dict(added=None, gap=10.0, excess=9.9)],
             parameters={"torque": {"torque_offset@slide": {"offset [N m]": 0.5}}},
             responses_not_modelled=[], seconds=1.0, verdict="explained", stop_reason="done")
    r.update(kw)
    return r


def test_payload_confounded_and_selected_gets_its_sentence():
    md = markdown(_result(), [], prismatic=["slide"])
    assert "Payload is both confounded with the refit and selected" in md
    assert "offset [N]: 0.5" in md and "offset [N m]" not in md
    md = markdown(_result(selected=[]), [])
    assert "is both confounded" not in md
