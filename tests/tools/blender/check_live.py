# Run by test_blender (tests/tools/test_blender.cpp) inside headless Blender:
#   blender -b --factory-startup --python-exit-code 1 --python check_live.py -- ADDON_DIR SEGMENT FRAMES OUT TIMEOUT_S
# Enables the tetrig live add-on (tools/blender/tetrig_live.py), connects it to SEGMENT through its
# operator and polls it exactly as its timer does (tetrig_live.poll_all; timers do not run in
# background mode) until FRAMES frames were applied. After each applied frame it reads the mesh
# object's vertices back from Blender (mesh data, and the evaluated depsgraph mesh for every
# tenth) and writes them to OUT in tetrig-shm-cat's --dump layout ("TSHMDMP1", then per frame
# uint64 instance id, uint64 frame id, uint32 vertex count, uint32 0, float32 xyz), and the
# object's triangles to OUT.tris (uint32 x 3 each). The C++ test compares both with what the
# producer published.
import os
import struct
import sys
import time

import bpy
import numpy as np

addon_dir, segment, frames, out, timeout_s = sys.argv[sys.argv.index("--") + 1:]
frames, timeout_s = int(frames), float(timeout_s)
bpy.ops.wm.read_factory_settings(use_empty=True)
sys.path.insert(0, addon_dir)
import tetrig_live  # noqa: E402

tetrig_live.register()
copy_path = "array.array" if tetrig_live.np is None else "numpy"
assert (copy_path == "array.array") == (os.environ.get("TETRIG_LIVE_NUMPY") == "0"), "TETRIG_LIVE_NUMPY not honoured"
assert bpy.ops.tetrig.connect(segment=segment, object_name="live", up="Y") == {"FINISHED"}
link = tetrig_live.links()[segment]
records = []
deadline = time.monotonic() + timeout_s
evaluated = 0
while len(records) < frames and time.monotonic() < deadline:
    if not tetrig_live.poll_all():
        time.sleep(0.0005)
        continue
    obj = bpy.data.objects["live"]
    co = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
    obj.data.vertices.foreach_get("co", co)
    if len(records) % 10 == 0:  # the evaluated mesh (what a render sees) holds the same vertices
        depsgraph = bpy.context.evaluated_depsgraph_get()
        ev = obj.evaluated_get(depsgraph)
        m = ev.to_mesh()
        ev_co = np.empty(len(m.vertices) * 3, dtype=np.float32)
        m.vertices.foreach_get("co", ev_co)
        ev.to_mesh_clear()
        assert np.array_equal(ev_co, co), "evaluated mesh differs from the mesh data"
        evaluated += 1
    records.append((link.instance_id, link.last_info["frame_id"], co))
if len(records) < frames:
    raise SystemExit("check_live: only %d of %d frames within %.0f s (status: %s)" % (len(records), frames, timeout_s, link.status))
obj = bpy.data.objects["live"]
assert abs(obj.rotation_euler[0] - 1.5707963) < 1e-6, "a Y-up rig stands on Blender's floor"
with open(out + ".tmp", "wb") as f:
    f.write(b"TSHMDMP1")
    for instance, frame_id, co in records:
        f.write(struct.pack("<QQII", instance, frame_id, len(co) // 3, 0))
        f.write(co.astype("<f4").tobytes())
os.replace(out + ".tmp", out)
tris = np.empty(len(obj.data.polygons) * 3, dtype=np.uint32)
assert all(p.loop_total == 3 for p in obj.data.polygons)
obj.data.polygons.foreach_get("vertices", tris)
tris.astype("<u4").tofile(out + ".tris")
print("check_live: %d frames (%d evaluated), ids %d..%d, %s, %d reads, %d retries, copies through %s" %
      (len(records), evaluated, records[0][1], records[-1][1], link.status, link.segment.reads, link.segment.retries, copy_path))
tetrig_live.unregister()
