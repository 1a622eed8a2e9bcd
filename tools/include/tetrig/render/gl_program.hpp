// One OpenGL program from a vertex and a fragment shader's source (GLSL), for the drawers of
// render/ and the viewer. Needs a current OpenGL 3.3 context.
#pragma once

namespace tetrig::render {

// Compiles both shaders and links them; returns the program (a GLuint). Throws
// std::runtime_error naming `what` and carrying the driver's log when a shader does not compile
// or the program does not link. The shaders themselves are deleted once linked.
unsigned linkProgram(const char* vertex_source, const char* fragment_source, const char* what);

}  // namespace tetrig::render
