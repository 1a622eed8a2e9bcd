# Run by test_blender (tests/tools/test_blender.cpp) inside headless Blender:
#   blender -b --factory-startup --python-exit-code 1 --python check_pc2.py -- ADDON_DIR FILE.pc2 FRAMES OUT
# Imports a `tetrig export` through the add-on's import operator (the rest OBJ, the PC2 on a Mesh
# Cache modifier), sets each scene frame of the comma-separated FRAMES and writes the evaluated
# depsgraph mesh's vertices to OUT in tetrig-shm-cat's --dump layout (instance id 0, "frame id" =
# the scene frame), and OUT.json with the scene and modifier settings the import made and the
# polygons' uvs and materials.
import json
import os
import struct
import sys

import bpy
import numpy as np

addon_dir, pc2, frames, out = sys.argv[sys.argv.index("--") + 1:]
bpy.ops.wm.read_factory_settings(use_empty=True)
sys.path.insert(0, addon_dir)
import tetrig_live  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_surface import surface  # noqa: E402



tetrig_live.register()
assert bpy.ops.tetrig.import_export(filepath=pc2) == {"FINISHED"}
obj = [o for o in bpy.data.objects if o.type == "MESH"][0]
scene = bpy.context.scene
with open(out + ".tmp", "wb") as f:
    f.write(b"TSHMDMP1")
    for frame in (int(x) for x in frames.split(",")):
        scene.frame_set(frame)
        ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        m = ev.to_mesh()
        co = np.empty(len(m.vertices) * 3, dtype=np.float32)
        m.vertices.foreach_get("co", co)
        ev.to_mesh_clear()
        f.write(struct.pack("<QQII", 0, frame, len(co) // 3, 0))
        f.write(co.astype("<f4").tobytes())
os.replace(out + ".tmp", out)
mod = obj.modifiers[0]
with open(out + ".json", "w") as f:
    json.dump({"modifier": mod.type, "cache_format": mod.cache_format, "frame_start": mod.frame_start,
               "scene_frame_start": scene.frame_start, "scene_frame_end": scene.frame_end, "fps": scene.render.fps,
               "fps_base": scene.render.fps_base, "rotation_x": obj.rotation_euler[0], "vertices": len(obj.data.vertices),
               "surface": surface(obj)}, f)
print("check_pc2: %s frames %s" % (obj.name, frames))
