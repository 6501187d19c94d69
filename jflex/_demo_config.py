"""Schema of ``configs/demo.yaml``, the config ``jflex demo`` reads (see :func:`jflex.cli.run_demo`)."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from ._schema import Strict

__all__ = ["DemoConfig"]

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Range = Annotated[list[float], Field(min_length=2, max_length=2)]


class LinkInertial(Strict):
    """One link's inertial in its DH frame: ``mass`` (+ ``com``, ``inertia``) or ``params``."""

    mass: Annotated[float, Field(gt=0)] | None = Field(None, description="kg")
    com: Vec3 | None = Field(None, description="centre of mass [m]")
    inertia: Annotated[list[float], Field(min_length=6, max_length=6)] | None = Field(
        None, description="Ixx, Ixy, Iyy, Ixz, Iyz, Izz about the centre of mass [kg m^2]")
    params: Annotated[list[float], Field(min_length=10, max_length=10)] | None = Field(
        None, description="the 10 inertial parameters")

    @model_validator(mode="after")
    def _one_form(self):
        if (self.mass is None) == (self.params is None):
            raise ValueError("expected 'mass' (kg, with com and inertia) or 'params' (10 numbers), not both or neither")
        return self


class GridConfig(Strict):
    q2_deg: Range = Field([-120.0, 120.0], description="range of joint 2 [deg]")
    q3_deg: Range = Field([-140.0, 140.0], description="range of joint 3 [deg]")
    n: Annotated[int, Field(ge=2)] = Field(61, description="points per axis")


class DemoConfig(Strict):
    robot: str = Field("case", description="'case': the diagnosed robot; or a robot config name (configs/robots) or URDF")
    links: Annotated[list[LinkInertial], Field(min_length=1)] | None = Field(
        None, description="link inertials replacing the robot config's")
    grid: GridConfig = Field(default_factory=GridConfig)
