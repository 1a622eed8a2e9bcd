// The OBJ and MTL readers behind a rig's texture coordinates and materials
// (tools/include/tetrig/rigbuild/obj_surface_attributes.hpp): indices in every form, malformed
// lines refused, map_Kd options, and the matching of fine triangles to the file's faces (merged
// vertices, a repaired surface, a missing material library). The whole path (build-rig and every
// export) is tested in test_export (ExportUv.*) and test_blender (BlenderUv.*).
#include "tetrig/rigbuild/obj_surface_attributes.hpp"

#include "temp_dir.hpp"

#include <gtest/gtest.h>

namespace tetrig::rigbuild {
namespace {

using test::TempDir;

TEST(ObjSurfaceData, IndicesInEveryForm) {
  const std::string obj =
      "# a quad and a triangle\nmtllib a.mtl\nmtllib a.mtl b c.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
      "vt 0 0\nvt 1 0 0.5\nvt 1\nvt 0 1\nvn 0 0 1\n"
      "usemtl red\nf 1/1 2/2/1 3/3 4/4\n"
      "usemtl blue\nf -4//1 -3 \\\n  -2/-1\n"
      "l 1 2\nf 1 2\nusemtl red\nf 1/1 3/3 4/4\n";
  std::string why;
  const std::optional<ObjSurfaceData> d = readObjSurfaceData(obj, &why);
  ASSERT_TRUE(d) << why;
  EXPECT_EQ(d->vertices, 4);
  ASSERT_EQ(d->uvs.size(), 4u);
  EXPECT_EQ(d->uvs[1], (std::array<double, 2>{1, 0}));  // w dropped
  EXPECT_EQ(d->uvs[2], (std::array<double, 2>{1, 0}));  // v missing: 0
  EXPECT_EQ(d->material_libraries, (std::vector<std::string>{"a.mtl", "a.mtl b c.mtl"}));
  EXPECT_EQ(d->materials, (std::vector<std::string>{"red", "blue"}));
  ASSERT_EQ(d->faces.size(), 3u);  // the line and the two-corner face are not surface faces
  EXPECT_EQ(d->faces[0].corners, 4);
  EXPECT_EQ(d->faces[0].material, 0);
  EXPECT_EQ(d->faces[1].material, 1);
  EXPECT_EQ(d->faces[2].material, 0);
  EXPECT_EQ(d->corner_vertex, (std::vector<std::int32_t>{0, 1, 2, 3, 0, 1, 2, 0, 2, 3}));
  EXPECT_EQ(d->corner_uv, (std::vector<std::int32_t>{0, 1, 2, 3, -1, -1, 3, 0, 2, 3}));
}

TEST(ObjSurfaceData, MalformedIndicesAreRefused) {
  const std::string head = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\n";
  auto why = [&](const std::string& tail) {
    std::string w;
    EXPECT_FALSE(readObjSurfaceData(head + tail, &w)) << tail;
    return w;
  };
  EXPECT_NE(why("f 0 1 2\n").find("malformed vertex index '0'"), std::string::npos);
  EXPECT_NE(why("f 1 2 4\n").find("names vertex 4 of 3"), std::string::npos);
  EXPECT_NE(why("f 1/1 2/2 3/1\n").find("names texture coordinate 2 of 1"), std::string::npos);
  EXPECT_NE(why("f 1/x 2 3\n").find("malformed texture index"), std::string::npos);
  EXPECT_NE(why("f -4 2 3\n").find("relative index before the first vertex"), std::string::npos);
  EXPECT_NE(why("vt\n").find("vt line has no number"), std::string::npos);
  EXPECT_NE(why("vt 0 nan\n").find("malformed number"), std::string::npos);
  EXPECT_TRUE(readObjSurfaceData(head + "f 1 2 3\n"));
}

TEST(ObjSurfaceData, MtlDiffuseColourAndTexture) {
  const std::vector<MtlMaterial> m = readMtl(
      "newmtl a\nKd 0.5 0.25 1\nmap_Kd -s 1 1 1 -o 0.5 -bm 0.2 -clamp on tex\\skin tone.png\n"
      "newmtl b\nKd spectral b.rfl\nmap_Ka ignored.png\nnewmtl c d\nmap_Kd -blendu off  plain.jpg \n");
  ASSERT_EQ(m.size(), 3u);
  EXPECT_EQ(m[0].name, "a");
  ASSERT_TRUE(m[0].diffuse_color);
  EXPECT_EQ(*m[0].diffuse_color, Eigen::Vector3d(0.5, 0.25, 1));
  EXPECT_EQ(m[0].diffuse_texture, "tex/skin tone.png");
  EXPECT_FALSE(m[1].diffuse_color);
  EXPECT_EQ(m[1].diffuse_texture, "");
  EXPECT_EQ(m[2].name, "c d");
  EXPECT_EQ(m[2].diffuse_texture, "plain.jpg");
}

// A square of two quads in the file; the fine mesh as the import would give it (file vertex 4 a
// duplicate of vertex 1, merged into it; triangles in another order and one re-oriented).
TEST(ObjSurfaceData, FineTrianglesMatchTheFilesFacesAndTakeTheirOrder) {
  const TempDir dir;
  dir.write("m.mtl", "newmtl left\nKd 1 0 0\nnewmtl right\nmap_Kd ../tex/r.png\n");
  const auto obj = dir.write("sq.obj",
                             "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 1 0 0\nv 2 0 0\nv 2 1 0\n"
                             "vt 0 0\nvt 0.5 0\nvt 0.5 1\nvt 0 1\nvt 0.6 0\nvt 1 0\nvt 1 1\nvt 0.6 1\n"
                             "usemtl left\nf 1/1 2/2 3/3 4/4\nusemtl right\nf 5/5 6/6 7/7 3/8\n");
  const std::vector<std::int32_t> file_to_fine = {0, 1, 2, 3, 1, 4, 5};
  Triangles tris(4, 3);
  tris << 1, 4, 5,  // right quad
      0, 1, 2,      // left quad
      1, 5, 2,      // right quad
      0, 3, 2;      // left quad, re-oriented (0 2 3 in the file's winding)
  std::string note;
  const std::optional<RigSurfaceAttributes> s = objSurfaceAttributes(obj, file_to_fine, tris, &note);
  ASSERT_TRUE(s) << note;
  Triangles expected(4, 3);
  expected << 0, 1, 2, 0, 3, 2, 1, 4, 5, 1, 5, 2;
  EXPECT_EQ(tris, expected);  // the file's face order, stable within a face
  Triangles uvs(4, 3);
  uvs << 0, 1, 2, 0, 3, 2, 4, 5, 6, 4, 6, 7;  // vertex 1 (= file 2 and 5) takes each face's own vt
  EXPECT_EQ(s->corner_uvs, uvs);
  EXPECT_EQ(s->triangle_materials, (std::vector<std::int32_t>{0, 0, 1, 1}));
  ASSERT_EQ(s->materials.size(), 2u);
  EXPECT_EQ(s->materials[0].diffuse_color, Eigen::Vector3d(1, 0, 0));
  EXPECT_EQ(s->materials[1].diffuse_texture, "../tex/r.png");
  EXPECT_EQ(s->uvs.rows(), 8);
  EXPECT_EQ(note, "texture coordinates and materials of sq.obj kept: 8 uvs on 4 of 4 triangles, 2 materials (1 with a texture)");

  // A triangle on no face of the file (the surface was repaired): nothing kept, order unchanged.
  Triangles odd(2, 3);
  odd << 0, 1, 2, 0, 1, 5;
  const Triangles before = odd;
  EXPECT_FALSE(objSurfaceAttributes(obj, file_to_fine, odd, &note));
  EXPECT_EQ(odd, before);
  EXPECT_EQ(note, "texture coordinates not kept: 1 fine triangle lies on no face of sq.obj (the surface was repaired)");

  // The library missing: the names are kept; no vt and no usemtl: nothing to keep, no note.
  const auto lost = dir.write("lost.obj", "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n");
  Triangles one(1, 3);
  one << 0, 1, 2;
  const std::vector<std::int32_t> identity = {0, 1, 2};
  const std::optional<RigSurfaceAttributes> names = objSurfaceAttributes(lost, identity, one, &note);
  ASSERT_TRUE(names);
  EXPECT_EQ(names->materials[0].name, "x");
  EXPECT_EQ(names->uvs.rows(), 0);
  EXPECT_NE(note.find("material library gone.mtl not found"), std::string::npos) << note;
  const auto bare = dir.write("bare.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_FALSE(objSurfaceAttributes(bare, identity, one, &note));
  EXPECT_EQ(note, "");
}

}  // namespace
}  // namespace tetrig::rigbuild
