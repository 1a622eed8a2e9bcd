#!/usr/bin/env python3
"""The C API from Python through ctypes, against `tetrig export`, bit for bit.

The real rig (SMPL male + HDM05 markers, the capi_rig fixture) is driven through libtetrig.so with
the HDM05 clip's first FRAMES frames (read by the same library, tetrig_clip_frame), 3 iterations
each, no time limit, the default (accurate) settings. `tetrig export --iterations 3 --range 0:FRAMES`
writes the same frames into a PC2 point cache; every frame's positions must be the same bytes. The
triangles must be the rest OBJ's faces. Bad calls (NULL handle, short buffer, missing file) must
return their status and a text.

usage: test_capi_ctypes.py SOURCE_DIR LIBTETRIG TETRIG_EXE RIG [FRAMES]
Exit 0: passed; 1: failed; 77: skipped (the data is absent, outside CI).
"""
import ctypes
import math
import os
import struct
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
import tetrig_test_data as data  # noqa: E402

# tetrig.h's status values.
TETRIG_OK = 0
TETRIG_ERROR_INVALID_ARGUMENT = 1
TETRIG_ERROR_BUFFER_SIZE = 2
TETRIG_ERROR_FILE = 3
TETRIG_FRAME_POSE_HELD = 0x01


class FrameStats(ctypes.Structure):
    """tetrig_frame_stats, field for field."""
    _fields_ = [
        ("frames", ctypes.c_uint64),
        ("iterations", ctypes.c_int32),
        ("flags", ctypes.c_uint32),
        ("energy", ctypes.c_double),
        ("step_ns", ctypes.c_int64),
        ("pose_transfer_ns", ctypes.c_int64),
        ("total_ns", ctypes.c_int64),
        ("measured_markers", ctypes.c_int32),
        ("occluded_markers", ctypes.c_int32),
        ("blending_markers", ctypes.c_int32),
        ("unknown_markers", ctypes.c_int32),
        ("rejected_marker_samples", ctypes.c_int32),
    ]


def load_library(path):
    """libtetrig.so with the prototypes of the functions this test calls."""
    lib = ctypes.CDLL(path)
    rig_p, clip_p = ctypes.c_void_p, ctypes.c_void_p
    f32p, i32p = ctypes.POINTER(ctypes.c_float), ctypes.POINTER(ctypes.c_int32)
    protos = {
        "tetrig_version": (ctypes.c_char_p, []),
        "tetrig_last_error": (ctypes.c_char_p, []),
        "tetrig_rig_open": (rig_p, [ctypes.c_char_p, ctypes.c_void_p]),
        "tetrig_rig_close": (None, [rig_p]),
        "tetrig_rig_marker_count": (ctypes.c_int32, [rig_p]),
        "tetrig_rig_vertex_count": (ctypes.c_int32, [rig_p]),
        "tetrig_rig_triangle_count": (ctypes.c_int32, [rig_p]),
        "tetrig_rig_triangles": (ctypes.c_int, [rig_p, i32p, ctypes.c_size_t]),
        "tetrig_rig_bind_labels": (ctypes.c_int32, [rig_p, ctypes.POINTER(ctypes.c_char_p), ctypes.c_size_t]),
        "tetrig_rig_process_frame": (ctypes.c_int, [rig_p, f32p, ctypes.c_size_t, ctypes.c_int64, ctypes.c_int32, ctypes.c_int64,
                                                    f32p, ctypes.c_size_t, f32p, ctypes.c_size_t, ctypes.POINTER(FrameStats)]),
        "tetrig_clip_open": (clip_p, [ctypes.c_char_p]),
        "tetrig_clip_close": (None, [clip_p]),
        "tetrig_clip_marker_count": (ctypes.c_int32, [clip_p]),
        "tetrig_clip_marker_label": (ctypes.c_char_p, [clip_p, ctypes.c_int32]),
        "tetrig_clip_frame_count": (ctypes.c_int64, [clip_p]),
        "tetrig_clip_rate_hz": (ctypes.c_double, [clip_p]),
        "tetrig_clip_frame": (ctypes.c_int, [clip_p, ctypes.c_int64, f32p, ctypes.c_size_t, ctypes.POINTER(ctypes.c_int64)]),
    }
    for name, (restype, argtypes) in protos.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = restype, argtypes
    return lib


failures = 0


def check(cond, what):
    global failures
    if not cond:
        failures += 1
        print(f"FAILED: {what}")


def read_pc2(path):
    """(points, samples, [bytes of each sample]) of a PC2 point cache."""
    with open(path, "rb") as f:
        blob = f.read()
    magic, version, points, _start, _rate, samples = struct.unpack_from("<12sii ffi", blob, 0)
    check(magic == b"POINTCACHE2\0" and version == 1, f"{path}: not a PC2 file")
    size = points * 3 * 4
    frames = [blob[32 + k * size: 32 + (k + 1) * size] for k in range(samples)]
    check(len(blob) == 32 + samples * size, f"{path}: {len(blob)} bytes for {samples} samples of {points} points")
    return points, samples, frames


def obj_faces(path):
    """The 0-based vertex indices of an OBJ's faces, in order."""
    out = []
    with open(path) as f:
        for line in f:
            if line.startswith("f "):
                out.extend(int(corner.split("/")[0]) - 1 for corner in line.split()[1:])
    return out


def main():
    source_dir, lib_path, tetrig, rig_path = sys.argv[1:5]
    frames = int(sys.argv[5]) if len(sys.argv) > 5 else 240
    clip_path = data.require(source_dir, data.CLIP)
    if not os.path.exists(rig_path):
        print(f"FAILED: the rig {rig_path} is missing (the capi_rig fixture builds it: tests/capi/make_rig.py)")
        return 1
    lib = load_library(lib_path)

    # Errors: a missing file, a NULL handle, a short buffer: a status and a text, no crash.
    check(lib.tetrig_rig_open(b"/nonexistent/tetrig/missing.rig", None) is None, "a missing rig opened")
    check(b"missing.rig" in lib.tetrig_last_error(), f"the error names the file: {lib.tetrig_last_error()!r}")
    check(lib.tetrig_rig_vertex_count(None) == -1, "a NULL handle has a vertex count")
    check(b"NULL" in lib.tetrig_last_error(), "the error says NULL")
    one = (ctypes.c_float * 3)()
    check(lib.tetrig_rig_process_frame(None, one, 1, 0, 3, 0, one, 3, None, 0, None) == TETRIG_ERROR_INVALID_ARGUMENT, "NULL rig frame")
    check(lib.tetrig_clip_open(b"/nonexistent/tetrig/missing.c3d") is None, "a missing clip opened")

    rig = lib.tetrig_rig_open(rig_path.encode(), None)
    clip = lib.tetrig_clip_open(clip_path.encode())
    if not rig or not clip:
        print(f"FAILED: open: {lib.tetrig_last_error().decode()}")
        return 1
    markers = lib.tetrig_clip_marker_count(clip)
    labels = (ctypes.c_char_p * markers)(*[lib.tetrig_clip_marker_label(clip, i) for i in range(markers)])
    bound = lib.tetrig_rig_bind_labels(rig, labels, markers)
    check(bound == lib.tetrig_rig_marker_count(rig) and bound > 30, f"bound {bound} of {lib.tetrig_rig_marker_count(rig)} rig markers")
    vertices = lib.tetrig_rig_vertex_count(rig)
    n = vertices * 3
    check(abs(lib.tetrig_clip_rate_hz(clip) - 120.0) < 1e-9, "HDM05 is 120 Hz")
    check(lib.tetrig_clip_frame_count(clip) >= frames, "the clip is long enough")

    with tempfile.TemporaryDirectory(prefix="tetrig-capi-ctypes-") as tmp:
        pc2 = os.path.join(tmp, "anim.pc2")
        cmd = [tetrig, "export", "--rig", rig_path, "--clip", clip_path, "--out", pc2, "--range", f"0:{frames}", "--iterations", "3", "--quiet"]
        result = subprocess.run(cmd, capture_output=True, text=True)
        if result.returncode != 0:
            print(f"FAILED: {' '.join(cmd)}: exit {result.returncode}\n{result.stderr}")
            return 1
        points, samples, expected = read_pc2(pc2)
        check(points == vertices and samples == frames, f"PC2 of {points} points x {samples} samples; the rig has {vertices}, {frames} asked")
        # The triangles through ctypes are the rest OBJ's faces.
        triangles = (ctypes.c_int32 * (lib.tetrig_rig_triangle_count(rig) * 3))()
        check(lib.tetrig_rig_triangles(rig, triangles, len(triangles)) == TETRIG_OK, "triangles")
        check(list(triangles) == obj_faces(os.path.join(tmp, "anim.rest.obj")), "the triangles differ from the exported rest OBJ's faces")

        xyz = (ctypes.c_float * (markers * 3))()
        x = (ctypes.c_float * n)()
        t = ctypes.c_int64()
        stats = FrameStats()
        # A short output buffer is refused.
        check(lib.tetrig_clip_frame(clip, 0, xyz, len(xyz), ctypes.byref(t)) == TETRIG_OK, "clip frame 0")
        check(lib.tetrig_rig_process_frame(rig, xyz, markers, t, 3, 0, x, n - 1, None, 0, None) == TETRIG_ERROR_BUFFER_SIZE, "a short buffer")
        check(b"positions holds" in lib.tetrig_last_error(), f"the error says why: {lib.tetrig_last_error()!r}")

        differing = []
        first = last = None
        for f in range(frames):
            check(lib.tetrig_clip_frame(clip, f, xyz, len(xyz), ctypes.byref(t)) == TETRIG_OK, f"clip frame {f}")
            status = lib.tetrig_rig_process_frame(rig, xyz, markers, t, 3, 0, x, n, None, 0, ctypes.byref(stats))
            if status != TETRIG_OK:
                check(False, f"frame {f}: status {status}: {lib.tetrig_last_error().decode()}")
                break
            check(stats.iterations == 3 and not (stats.flags & TETRIG_FRAME_POSE_HELD), f"frame {f}: {stats.iterations} iterations")
            got = bytes(x)
            if got != expected[f]:
                differing.append(f)
            if f == 0:
                first = struct.unpack(f"<{n}f", got)
            last = struct.unpack(f"<{n}f", got)
        check(not differing, f"{len(differing)} of {frames} frames differ from tetrig export's, the first {differing[:5]}")
        check(all(math.isfinite(v) for v in last), "non-finite positions")
        moved = max(math.dist(first[3 * v:3 * v + 3], last[3 * v:3 * v + 3]) for v in range(vertices))
        print(f"{frames} frames equal to tetrig export's bit for bit: {not differing}; the mesh moved up to {moved:.3f} m")
        check(moved > 0.05, f"the mesh moved {moved:.3f} m only: the comparison would not mean much")

    lib.tetrig_clip_close(clip)
    lib.tetrig_rig_close(rig)
    if failures:
        print(f"{failures} checks FAILED")
        return 1
    print("passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
