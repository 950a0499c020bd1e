"""Scenes of the stream and outlet tests (tests/test_streams.py and the MPI case stream_case.py)."""
from __future__ import annotations

GLASS = {"density": 2500.0, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3}
# The free-fall stream: dt is given (no contacts form: particles are inserted apart and fall apart).
FALL_DT = 2.0e-5


# A region the falling_stream's events overfill (its candidates often find no room: the stream falls
# behind and catches up), and one with room for every event of the rate tests.
SMALL_REGION = [[0.0, 0.0, 0.05], [0.012, 0.006, 0.054]]
LARGE_REGION = [[0.0, 0.0, 0.05], [0.03, 0.03, 0.054]]


def falling_stream(out, end=0.05, rate=6000.0, stop=0.03, interval=0.004, outlet_height=0.045, mass_rate=None,
                   box_outlet=None, region=SMALL_REGION):
    """A stream falling from `region` (at -0.2 m/s, under gravity) through an outlet plane below it."""
    insert = {"kind": "stream", "region": {"box": region},
              "velocity": [0.0, 0.0, -0.2], "stop": stop, "interval": interval, "seed": 11, "max_attempts": 20}
    if mass_rate is not None:
        insert["mass_rate"] = mass_rate
    else:
        insert["rate"] = rate
    outlets = [{"name": "floor", "kind": "plane", "point": [0.0, 0.0, outlet_height], "normal": [0.0, 0.0, -1.0]}]
    if box_outlet is not None:
        outlets.insert(0, {"name": "catch", "kind": "box", "box": box_outlet})
    return {
        "time": {"end": end, "dt": FALL_DT},
        "materials": {"glass": dict(GLASS)},
        "interactions": {"default": {"restitution": 0.5, "friction": 0.3}},
        "particles": [{"name": "feed", "material": "glass", "radius": {"min": 0.0008, "max": 0.0012},
                       "insert": insert}],
        "outlets": outlets,
        "output": {"dir": str(out), "every": 0.005, "particles": []},
    }


def pile_stream(out, end, checkpoint_every):
    """A stream poured onto a floor plane: grains land on each other (pair and wall contacts with
    tangential history) while the stream still inserts, next to a box outlet taking some of them."""
    return {
        "time": {"end": end, "dt": "auto"},
        "materials": {"glass": dict(GLASS)},
        "interactions": {"default": {"restitution": 0.5, "friction": 0.4}},
        "particles": [{"name": "feed", "material": "glass", "radius": {"min": 0.0009, "max": 0.0011},
                       "insert": {"kind": "stream", "region": {"box": [[0.0, 0.0, 0.004], [0.01, 0.01, 0.008]]},
                                  "rate": 8000.0, "velocity": [0.0, 0.0, -0.3], "seed": 5, "interval": 0.002}}],
        "walls": [{"name": "floor", "kind": "plane", "material": "glass", "point": [0, 0, 0], "normal": [0, 0, 1]}],
        "outlets": [{"name": "corner", "kind": "box", "box": [[-1.0, -1.0, -1.0], [0.002, 1.0, 1.0]]}],
        "output": {"dir": str(out), "every": checkpoint_every, "particles": []},
        "checkpoint": {"every": checkpoint_every, "keep": 100},
    }


# The heated pour (heated_pile_stream): the stream's grains start at STREAM_TEMPERATURE, the floor is held at
# FLOOR_TEMPERATURE and the side wall at SIDE_TEMPERATURE; GRAIN_HEAT_CAPACITY is small enough for the walls to
# move heat visibly within the run (dt sum(H) / (m c) ~ 0.08 at its deepest contacts: stable).
STREAM_TEMPERATURE, FLOOR_TEMPERATURE, SIDE_TEMPERATURE = 300.0, 400.0, 250.0
GRAIN_HEAT_CAPACITY = 0.02


def heated_pile_stream(out, end=0.03, output_every=0.002, checkpoint_every=0.01):
    """pile_stream with heat on: grains poured at 300 K onto a floor held at 400 K beside a side wall (y = 0)
    held at 250 K; the corner outlet takes the grains reaching x < 2 mm and the domain box those rolling past
    y = 10.2 mm, so particles are inserted and removed, by both paths, while the walls heat and cool them."""
    scene = pile_stream(out, end, checkpoint_every)
    scene["output"]["every"] = output_every
    scene["materials"]["glass"].update(conductivity=1.0, heat_capacity=GRAIN_HEAT_CAPACITY)
    scene["materials"]["steel"] = {"density": 7800.0, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3,
                                   "conductivity": 50.0}
    scene["particles"][0]["initial_temperature"] = STREAM_TEMPERATURE
    scene["walls"][0].update(material="steel", temperature=FLOOR_TEMPERATURE)
    scene["walls"].append({"name": "side", "kind": "plane", "material": "steel", "point": [0.0, 0.0, 0.0],
                           "normal": [0.0, 1.0, 0.0], "temperature": SIDE_TEMPERATURE})
    scene["domain"] = {"box": [[-1.0, -1.0, -1.0], [1.0, 0.0102, 1.0]]}
    return scene
