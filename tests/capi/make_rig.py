#!/usr/bin/env python3
"""Fixture capi_rig: builds the real rig the C API and install tests drive, with `tetrig build-rig`:
the SMPL male (human_man.obj) rigged to the HDM05 clip's 41 markers, 1500 tet vertices (the live
benchmarks' size) and the default coarse level. Kept between runs while it is newer than the tetrig
command that built it.

usage: make_rig.py SOURCE_DIR TETRIG_EXE OUT.rig
"""
import os
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
import tetrig_test_data as data  # noqa: E402


def main():
    source_dir, tetrig, out = sys.argv[1:4]
    mesh = data.require(source_dir, data.MESH)
    clip = data.require(source_dir, data.CLIP)
    if os.path.exists(out) and os.path.getmtime(out) > os.path.getmtime(tetrig):
        print(f"{out}: up to date")
        return 0
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    cmd = [tetrig, "build-rig", "--mesh", mesh, "--clip", clip, "--out", out, "--tet-vertices", "1500", "--quiet"]
    print(" ".join(cmd), flush=True)
    result = subprocess.run(cmd)
    if result.returncode != 0 or not os.path.exists(out):
        print(f"FAILED: tetrig build-rig exited with {result.returncode}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
