"""jflex case init on a log whose angle columns are headed by the joints' own names (as many
controllers and FIGAROH-style logs write them): the bare names are the positions; a name with a
role word (velocity, current) keeps that role."""

import yaml
from jflex_family import generate as G


def test_bare_joint_names_are_the_angle_columns(tmp_path):
    from jflex.gap.case._init import case_init

    G.write_robot(tmp_path, "planar2")  # joints shoulder, elbow
    (tmp_path / "log.csv").write_text("time,Shoulder,ELBOW,shoulder_vel,elbow_vel,current_1,current_2\n"
                                      "0,0,0,0,0,0,0\n0.01,0.1,0.2,1,2,0.5,0.6\n")
    cfg = yaml.safe_load(case_init(tmp_path / "robot.yaml", tmp_path / "log.csv").read_text())
    cols = cfg["datasets"][0]["columns"]
    assert cols["position"] == {"shoulder": "Shoulder", "elbow": "ELBOW"}
    assert cols["velocity"] == {"shoulder": "shoulder_vel", "elbow": "elbow_vel"}
    assert cols["torque"] == {"shoulder": "current_1", "elbow": "current_2"}
    assert sorted(cfg["datasets"][0]["scale"]) == ["current_1", "current_2"]
