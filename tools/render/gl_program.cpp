// render/gl_program.hpp: compile, link, and report the driver's log on failure.
#include "tetrig/render/gl_program.hpp"

#include <epoxy/gl.h>

#include <stdexcept>
#include <string>

namespace tetrig::render {

namespace {

GLuint compile(GLenum type, const char* source, const char* what) {
  const GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &source, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[1024] = {};
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    glDeleteShader(s);
    throw std::runtime_error(std::string(what) + ": OpenGL " +
                             (type == GL_VERTEX_SHADER ? "vertex" : "fragment") + " shader does not compile: " + log);
  }
  return s;
}

}  // namespace

unsigned linkProgram(const char* vertex_source, const char* fragment_source, const char* what) {
  const GLuint v = compile(GL_VERTEX_SHADER, vertex_source, what);
  GLuint f = 0;
  try {
    f = compile(GL_FRAGMENT_SHADER, fragment_source, what);
  } catch (...) {
    glDeleteShader(v);
    throw;
  }
  const GLuint p = glCreateProgram();
  glAttachShader(p, v);
  glAttachShader(p, f);
  glLinkProgram(p);
  glDeleteShader(v);
  glDeleteShader(f);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[1024] = {};
    glGetProgramInfoLog(p, sizeof log, nullptr, log);
    glDeleteProgram(p);
    throw std::runtime_error(std::string(what) + ": OpenGL program does not link: " + log);
  }
  return p;
}

}  // namespace tetrig::render
