#!/usr/bin/python3
"""Writes the example scripts of this directory (orbit.jsonl, door-light.jsonl,
walking-object.jsonl) for the embedded Cornell box. The .jsonl files are committed; run
this after changing it: /usr/bin/python3 examples/gen_examples.py

The box (scenes/cornell-box/cornell-box.obj, metres, +Y up): x in [0, 0.556] (green wall at
x = 0, red wall at x = 0.556), y in [0, 0.549] (ceiling light at y = 0.5488, x 0.213..0.343,
z 0.227..0.332), z in [0, 0.559] (back wall at z = 0.559, open front at z = 0). Short block
x 0.08..0.29, z 0.065..0.272, 0.165 high; tall block x 0.265..0.472, z 0.247..0.456, 0.33 high.
"""
import json
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))


def r(v):
    return round(v, 4) + 0.0  # + 0.0 turns -0.0 into 0.0


def write(name, header, lines):
    with open(os.path.join(HERE, name), "w") as f:
        for h in header:
            f.write("# " + h + "\n")
        for m in lines:
            f.write(json.dumps(m, separators=(", ", ": ")) + "\n")


def orbit():
    # A cool white point light circling 18 cm around the box's vertical axis, 15 cm under
    # the ceiling (above the tall block): 72 steps at 12 Hz, one turn in 6 s, ending where
    # it started so --loop runs seamlessly (the first step is at 1/12 s, not 0).
    # 0.3 cd, measured on the embedded bake (mean lightmap irradiance, bounces 0,
    # progressive, converged): the ceiling light alone gives (0.54, 0.35, 0.10) W/m^2; this
    # light at its first position adds (1.36, 0.96, 0.90): clearly visible, and the ceiling
    # light still counts. At "a few candela" the ceiling light would all but vanish (a
    # white 2 cd point light at the centre adds ~11 W/m^2).
    cx, cy, cz, rad = 0.278, 0.40, 0.28, 0.18
    lines = []
    for i in range(1, 73):
        a = 2 * math.pi * i / 72
        lines.append({"at": r(i / 12), "type": "light.set",
                      "light": {"id": "orbit", "type": "point", "color": [0.7, 0.85, 1.0], "intensity": 0.3,
                                "position": [r(cx + rad * math.cos(a)), cy, r(cz + rad * math.sin(a))]}})
    write("orbit.jsonl", ["A point light orbiting inside the Cornell box: 72 steps at 12 Hz (6 s per turn).",
                          "lucentctl script examples/orbit.jsonl [--loop] [--speed 2]"], lines)


def door_light():
    # Light through a "door": a 15 x 35 cm area light in the open front of the box, at its
    # red (x = 0.556) side, shining in (+z). It fades in over 1.5 s (smoothstep, 10 Hz),
    # stays on for 2 s, fades out over 1 s, then is removed. At 10 nits it adds, measured as
    # for orbit, (0.78, 0.43, 0.24) W/m^2 to the ceiling light's (0.54, 0.35, 0.10).
    full = 10.0
    light = {"id": "door", "type": "area", "color": [1.0, 0.85, 0.6], "position": [0.43, 0.2, 0.002],
             "direction": [0, 0, 1], "shape": "quad", "size": [0.15, 0.35], "tangent": [1, 0, 0]}
    lines = []

    def step(at, k):
        lines.append({"at": r(at), "type": "light.set", "light": dict(light, intensity=r(full * k))})

    for i in range(16):  # 0 .. 1.5 s
        t = i / 15
        step(i * 0.1, t * t * (3 - 2 * t))
    for i in range(1, 11):  # 3.5 .. 4.5 s
        t = 1 - i / 10
        step(3.5 + i * 0.1, t * t * (3 - 2 * t))
    lines.append({"at": 5.0, "type": "light.remove", "light_id": "door"})
    write("door-light.jsonl", ["A light fading in through a door at the front of the box, on for 2 s, then off.",
                               "lucentctl script examples/door-light.jsonl"], lines)


def walking_object():
    # The 10 cm `cube` asset (base centred on its origin) tumbles into the box through the
    # open front, rolling over its bottom edge (90 degrees per step, 6 frames per step at
    # 12 Hz), 4 steps from z = -0.25 to z = 0.15 in the free floor between the red wall and
    # the blocks (x = 0.43), pauses, rolls back out and is removed. After a full roll a cube
    # looks as before, so each step restarts from the identity rotation one cube further.
    x, half = 0.43, 0.05
    lines = []
    t = [0.0]

    def put(pos, q):
        lines.append({"at": r(t[0]), "type": "object.set",
                      "object": {"id": "walker", "asset": "cube", "translation": [x, r(pos[0]), r(pos[1])],
                                 "rotation": [r(q[0]), 0, 0, r(q[1])]}})
        t[0] += 1 / 12

    def roll(z0, sign):
        # pivot on the bottom edge ahead (sign = +1: +z) of the cube whose base centre is z0
        pz = z0 + sign * half
        for k in range(1, 7):
            th = math.radians(15 * k)
            # the origin (base centre) relative to the pivot, (0, 0, -sign*half), rotated
            # by sign*th about +x
            y = half * math.sin(th)
            z = pz - sign * half * math.cos(th)
            a = sign * th / 2
            put((y, z) if k < 6 else (0, z0 + 2 * sign * half), (math.sin(a), math.cos(a)) if k < 6 else (0, 1))
        return z0 + 2 * sign * half

    z = -0.25
    put((0, z), (0, 1))
    for _ in range(4):
        z = roll(z, +1)
    t[0] += 1.0  # pause
    for _ in range(4):
        z = roll(z, -1)
    lines.append({"at": r(t[0] + 0.5), "type": "object.remove", "object_id": "walker"})
    write("walking-object.jsonl", ["The `cube` asset rolling into the box over its edges, back out, then removed.",
                                   "lucentctl script examples/walking-object.jsonl"], lines)


orbit()
door_light()
walking_object()
