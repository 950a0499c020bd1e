"""Coupled DEM-FEM scenes shared by tests/test_coupling_*.py and the coupling MPI cases."""
from __future__ import annotations

import math

# The reference ball-on-block case: a soft heavy ball on a stiff steel block.
BALL_RADIUS = 0.2
BALL = {"density": 10000.0, "youngs_modulus": 1e7, "poisson_ratio": 0.2}
BLOCK_STEEL = {"density": 7850.0, "youngs_modulus": 2e10, "poisson_ratio": 0.29}


def effective_modulus(a: dict, b: dict) -> float:
    return 1.0 / ((1 - a["poisson_ratio"] ** 2) / a["youngs_modulus"] + (1 - b["poisson_ratio"] ** 2) / b["youngs_modulus"])


def sphere_mass(radius: float, density: float) -> float:
    return 4.0 / 3.0 * math.pi * radius**3 * density


def ball_on_block(element="P1", dt=1e-4, fem_every=1, height=1.0, block_modulus=None, restitution=0.2,
                  cells=(2, 2, 1), end=1.0, mass="lumped", rigid=None, speed=0.0):
    """Sphere R = 0.2 m dropped from centre height `height` onto a 1 x 1 x 0.5 m block clamped at its base.

    rigid: None (deformable block), "mesh" (the block's top as a rigid plane wall, for the limit test)."""
    steel = dict(BLOCK_STEEL)
    if block_modulus is not None:
        steel["youngs_modulus"] = block_modulus
    scene = {
        "time": {"end": end, "dt": dt},
        "gravity": [0.0, 0.0, -9.81],
        "materials": {"ball": dict(BALL), "steel": steel},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": restitution, "friction": 0.0}},
        "particles": [{"name": "b", "material": "ball", "radius": BALL_RADIUS,
                       "insert": {"kind": "list", "positions": [[0.5, 0.5, height]],
                                  "velocities": [[0.0, 0.0, -speed]]}}],
        "coupling": {"fem_every": fem_every},
    }
    if rigid == "plane":
        scene["walls"] = [{"name": "block", "kind": "plane", "point": [0, 0, 0.5], "normal": [0, 0, 1],
                           "material": "steel"}]
    else:
        scene["solids"] = [{"name": "block", "mesh": {"box": [[0, 0, 0], [1, 1, 0.5]], "cells": list(cells)},
                            "material": "steel", "element": element, "mass": mass, "fixed": ["zmin"],
                            "contact": ["zmax"]}]
    return scene


def free_block_impact(element="P1", dt=2e-5, speed=1.0, restitution=1.0, fem_every=1, cells=(2, 2, 2),
                      offset=(0.0, 0.0), friction=0.0, tangential=0.0):
    """A particle (R = 0.05 m) hits the top of a free 0.2 m elastic cube; no gravity, no supports."""
    return {
        "time": {"end": 1.0, "dt": dt},
        "gravity": [0.0, 0.0, 0.0],
        "materials": {"grain": {"density": 2000.0, "youngs_modulus": 1e8, "poisson_ratio": 0.25},
                      "rubber": {"density": 1000.0, "youngs_modulus": 2e8, "poisson_ratio": 0.3}},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": restitution, "friction": friction}},
        "particles": [{"name": "p", "material": "grain", "radius": 0.05,
                       "insert": {"kind": "list", "positions": [[0.1 + offset[0], 0.1 + offset[1], 0.2 + 0.05 + 0.002]],
                                  "velocities": [[tangential, 0.0, -speed]]}}],
        "solids": [{"name": "block", "mesh": {"box": [[0, 0, 0], [0.2, 0.2, 0.2]], "cells": list(cells)},
                    "material": "rubber", "element": element, "contact": ["zmax"]}],
        "coupling": {"fem_every": fem_every},
    }


def pile_on_plate(element="P1", count=200, dt=None, cells=(4, 4, 1), fem_every=1, seed=3, plate_damping=2000.0,
                  top=0.1):
    """Particles (r ~ 5 mm) settling in a frictionless box onto a 0.2 x 0.2 x 0.02 m plate clamped at its two
    ends (x = 0, 0.2: groups xmin, xmax never share a node, so their reactions add up).  The side walls are frictionless (their normals are horizontal), so they carry none of the weight.
    plate_damping: Rayleigh alpha [1/s] of the plate (its first bending mode is ~9e3 rad/s: zeta ~ 0.1)."""
    return {
        "time": {"end": 1.0, "dt": dt if dt is not None else 4e-5},
        "gravity": [0.0, 0.0, -9.81],
        "materials": {"grain": {"density": 2500.0, "youngs_modulus": 1e7, "poisson_ratio": 0.3},
                      "side": {"density": 2500.0, "youngs_modulus": 1e7, "poisson_ratio": 0.3},
                      "plate": {"density": 2700.0, "youngs_modulus": 7e9, "poisson_ratio": 0.33}},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.1, "friction": 0.5},
                         "grain-side": {"model": "hertz_mindlin", "restitution": 0.1, "friction": 0.0}},
        "particles": [{"name": "grains", "material": "grain", "radius": {"min": 0.0045, "max": 0.0055},
                       "insert": {"kind": "random", "region": {"box": [[0.0555, 0.0555, 0.0256], [0.1445, 0.1445, top]]},
                                  "count": count, "seed": seed}}],
        "walls": [{"name": f"side_{k}", "kind": "plane", "point": point, "normal": normal, "material": "side"}
                  for k, (point, normal) in enumerate([([0.05, 0, 0], [1, 0, 0]), ([0.15, 0, 0], [-1, 0, 0]),
                                                        ([0, 0.05, 0], [0, 1, 0]), ([0, 0.15, 0], [0, -1, 0])])],
        "solids": [{"name": "plate", "mesh": {"box": [[0, 0, 0], [0.2, 0.2, 0.02]], "cells": list(cells)},
                    "material": "plate", "element": element, "fixed": ["xmin", "xmax"],
                    "damping": {"alpha": plate_damping, "beta": 0.0},
                    "contact": ["zmax"]}],
        "coupling": {"fem_every": fem_every},
    }
