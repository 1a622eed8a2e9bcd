# Run by test_blender (tests/tools/test_blender.cpp) inside headless Blender:
#   blender -b --factory-startup --python-exit-code 1 --python check_gltf.py -- ADDON_DIR FILE.glb|gltf FRAMES OUT
# Imports a `tetrig export` glTF through the add-on's import operator (Blender's own glTF importer,
# the scene rate set from the export first), sets each scene frame of the comma-separated FRAMES
# and writes the evaluated depsgraph mesh's vertices to OUT in tetrig-shm-cat's --dump layout
# (instance id 0, "frame id" = the scene frame), plus OUT.json (shape keys, scene settings).
import json
import os
import struct
import sys

import bpy
import numpy as np

addon_dir, path, frames, out = sys.argv[sys.argv.index("--") + 1:]
bpy.ops.wm.read_factory_settings(use_empty=True)
sys.path.insert(0, addon_dir)
import tetrig_live  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_surface import surface  # noqa: E402



tetrig_live.register()
assert bpy.ops.tetrig.import_export(filepath=path) == {"FINISHED"}
objs = [o for o in bpy.data.objects if o.type == "MESH"]
assert len(objs) == 1, "one mesh object"
obj = objs[0]
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
keys = obj.data.shape_keys
with open(out + ".json", "w") as f:
    json.dump({"shape_keys": len(keys.key_blocks) if keys else 0, "animated": bool(keys and keys.animation_data and keys.animation_data.action),
               "scene_frame_start": scene.frame_start, "scene_frame_end": scene.frame_end, "fps": scene.render.fps,
               "fps_base": scene.render.fps_base, "vertices": len(obj.data.vertices), "surface": surface(obj)}, f)
print("check_gltf: %s, %d shape keys, frames %s" % (obj.name, len(keys.key_blocks) if keys else 0, frames))
