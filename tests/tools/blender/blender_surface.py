# Shared by the headless Blender checks (check_gltf.py, check_pc2.py): what Blender holds of an
# imported mesh's polygons, uvs and materials, for test_blender to compare with the source asset.
import bpy


def surface(obj):
    """The object's polygons as Blender holds them: per polygon its material's name and per loop
    (vertex index, basis x, y, z, u, v); and per material the image files its nodes use."""
    me = obj.data
    uv = me.uv_layers.active
    slots = obj.material_slots
    polygons = []
    for p in me.polygons:
        loops = []
        for li in p.loop_indices:
            vi = me.loops[li].vertex_index
            co = me.vertices[vi].co
            t = uv.data[li].uv if uv else (0.0, 0.0)
            loops.append([vi, co.x, co.y, co.z, t[0], t[1]])
        material = slots[p.material_index].material if p.material_index < len(slots) else None
        polygons.append({"material": material.name if material else "", "loops": loops})
    images = {}
    for slot in slots:
        m = slot.material
        if m is not None and m.use_nodes:
            images[m.name] = [bpy.path.abspath(n.image.filepath) for n in m.node_tree.nodes if n.type == "TEX_IMAGE" and n.image]
    return {"uv_layers": len(me.uv_layers), "polygons": polygons, "images": images}
