#!/usr/bin/env python3
"""Writes the moving test scenes of docs/video.md into configs/video/scenes/.

Each held-out scene (configs/scenes/heldout_window.json, heldout_wide.json) gets motion at
speeds 0, 1, 2 and 4 px per sub-frame: the layers named below move in the directions given,
scaled so the fastest moves that many pixels per sub-frame; the others stand still.
"""
import json
import math
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent
SPEEDS = [0, 1, 2, 4]
# Layer name -> direction of motion (dx, dy), relative speeds (the longest is 1).
MOTION = {
    "heldout_window": {"leaf": (1.0, 0.2), "near leaf": (-0.8, 0.3), "red flowers": (0.5, 0.0)},
    "heldout_wide": None,  # every layer but the first, alternating directions
}


def moving(scene, name, speed):
    layers = scene["layers"]
    directions = MOTION[name]
    if directions is None:
        directions = {}
        for i, layer in enumerate(layers[1:]):
            angle = 0.7 * i
            directions[layer.get("name", str(i))] = (math.cos(angle), math.sin(angle) * 0.5)
    longest = max(math.hypot(*d) for d in directions.values())
    for i, layer in enumerate(layers):
        key = layer.get("name", str(i - 1))
        if key in directions and speed > 0:
            dx, dy = directions[key]
            layer["motion"] = {"shift": [round(speed * dx / longest, 3),
                                         round(speed * dy / longest, 3)]}
    scene["name"] = f"{name}-s{speed}"
    scene["description"] = (f"{name} with its layers moving up to {speed} px per sub-frame "
                            "(scripts/video_scenes.py)")
    return scene


def main():
    out = ROOT / "configs/video/scenes"
    out.mkdir(parents=True, exist_ok=True)
    for name in MOTION:
        for speed in SPEEDS:
            scene = json.loads((ROOT / f"configs/scenes/{name}.json").read_text())
            path = out / f"{name}-s{speed}.json"
            path.write_text(json.dumps(moving(scene, name, speed), indent=2) + "\n")
            print(path.relative_to(ROOT))


if __name__ == "__main__":
    main()
