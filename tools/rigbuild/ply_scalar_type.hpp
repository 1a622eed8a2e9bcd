// PLY scalar types by name (both spellings of the format: "uchar" and "uint8", ...). Shared by the
// rig builder's PLY readers (file_vertex_list.cpp) and the hostile-file check (check_surface_file.cpp).
// Rig builder internal.
#pragma once

#include <string_view>

namespace tetrig::rigbuild {

// Size in bytes and kind of the scalar type `t`; false for a name PLY does not define.
inline bool plyScalarType(std::string_view t, int& size, bool& is_float, bool& is_signed) {
  struct T {
    std::string_view a, b;
    int size;
    bool f, s;
  };
  static constexpr T kTypes[] = {{"char", "int8", 1, false, true},     {"uchar", "uint8", 1, false, false},
                                 {"short", "int16", 2, false, true},   {"ushort", "uint16", 2, false, false},
                                 {"int", "int32", 4, false, true},     {"uint", "uint32", 4, false, false},
                                 {"float", "float32", 4, true, true},  {"double", "float64", 8, true, true}};
  for (const T& k : kTypes) {
    if (t == k.a || t == k.b) {
      size = k.size;
      is_float = k.f;
      is_signed = k.s;
      return true;
    }
  }
  return false;
}

}  // namespace tetrig::rigbuild
