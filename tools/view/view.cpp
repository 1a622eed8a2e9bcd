// `tetrig view` (view/view.hpp, docs/view.md). One thread: poll GLFW events, poll the segment
// (tetrig_shm.h: open, newest frame, producer status, name status; the protocol of docs/shm.md
// section 3, as tetrig-shm-cat follows it), draw the newest frame into a multisampled
// offscreen target (the renderer's MeshDrawer + the overlay as a textured quad), blit it to
// the window, and read the same target back for --screenshot. With --markers (M) and a layout 1.1
// segment, the frame's marker block (tetrig_shm_read_latest_markers: the same frame as the mesh)
// is drawn as round dots coloured by state (MarkerDots below). With --dds the frames, the static
// data and the publisher's liveliness come from the performer's DDS topics instead
// (tetrig::dds::FrameSubscriber, docs/dds.md), each sample checked by FrameChecker.
#include "view.hpp"

#include "tetrig/render/camera.hpp"
#include "tetrig/render/gl_program.hpp"
#include "tetrig/render/mesh_drawer.hpp"
#include "tetrig/render/offscreen_target.hpp"
#include "tetrig/render/picture_sheet.hpp"
#include "tetrig/render/text_raster.hpp"
#include "tetrig_shm.h"
#if TETRIG_HAVE_DDS
#include "tetrig/dds/frame_subscriber.hpp"
#endif

#include <epoxy/gl.h>
// GLFW after epoxy: epoxy provides the GL declarations.
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdarg>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <thread>
#include <vector>

namespace tetrig::tools {

namespace {

using render::Image;

std::string g_glfw_error;  // the last GLFW error description (GLFW reports through a callback)

// Text from the segment (the rig name) with control and non-ASCII bytes as \xNN.
std::string printable(const char* text) {
  std::string out;
  for (const unsigned char* p = reinterpret_cast<const unsigned char*>(text); *p != 0; ++p) {
    if (*p < 0x20 || *p >= 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", *p);
      out += hex;
    } else {
      out += static_cast<char>(*p);
    }
  }
  return out;
}

std::string format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string format(const char* fmt, ...) {
  char buf[512];
  va_list args;
  va_start(args, fmt);
  std::vsnprintf(buf, sizeof buf, fmt, args);
  va_end(args);
  return buf;
}

std::string segmentName(const std::string& name) {
  if (name.empty()) throw std::invalid_argument("missing segment NAME (the --publish name of tetrig run / tetrig demo)");
  std::string n = name[0] == '/' ? name : "/" + name;
  if (n.size() > TETRIG_SHM_NAME_MAX || n.size() < 2 || n.find('/', 1) != std::string::npos) {
    throw std::invalid_argument("segment name '" + printable(name.c_str()) + "' must be 1-254 characters, with no '/' but an optional leading one");
  }
  return n;
}

// A textured quad in pixel coordinates (the overlay), alpha-blended over the bound framebuffer.
class OverlayQuad {
 public:
  OverlayQuad() {
    const char* vs = R"(#version 330 core
uniform vec4 u_rect;  // x0, y0, x1, y1 in normalized device coordinates
out vec2 v_uv;
void main() {
  vec2 c = vec2((gl_VertexID & 1) != 0 ? 1.0 : 0.0, (gl_VertexID & 2) != 0 ? 1.0 : 0.0);
  v_uv = vec2(c.x, 1.0 - c.y);
  gl_Position = vec4(mix(u_rect.xy, u_rect.zw, c), 0.0, 1.0);
}
)";
    const char* fs = R"(#version 330 core
in vec2 v_uv;
uniform sampler2D u_image;
out vec4 o_color;
void main() { o_color = texture(u_image, v_uv); }
)";
    program_ = render::linkProgram(vs, fs, "viewer overlay");
    glGenVertexArrays(1, &vao_);
    glGenTextures(1, &texture_);
    glBindTexture(GL_TEXTURE_2D, texture_);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  }
  OverlayQuad(const OverlayQuad&) = delete;
  OverlayQuad& operator=(const OverlayQuad&) = delete;
  ~OverlayQuad() {
    glDeleteTextures(1, &texture_);
    glDeleteVertexArrays(1, &vao_);
    glDeleteProgram(program_);
  }
  void upload(const Image& image) {
    glBindTexture(GL_TEXTURE_2D, texture_);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, image.width, image.height, 0, GL_RGBA, GL_UNSIGNED_BYTE, image.rgba.data());
    width_ = image.width;
    height_ = image.height;
  }
  // Draws the image with its top-left corner at pixel (x, y) of a viewport of `vw` x `vh`.
  void draw(int x, int y, int vw, int vh) const {
    if (width_ == 0) return;
    const float x0 = 2.0f * static_cast<float>(x) / static_cast<float>(vw) - 1.0f;
    const float x1 = 2.0f * static_cast<float>(x + width_) / static_cast<float>(vw) - 1.0f;
    const float y0 = 1.0f - 2.0f * static_cast<float>(y + height_) / static_cast<float>(vh);
    const float y1 = 1.0f - 2.0f * static_cast<float>(y) / static_cast<float>(vh);
    glViewport(0, 0, vw, vh);
    glDisable(GL_DEPTH_TEST);
    glEnable(GL_BLEND);
    glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    glUseProgram(program_);
    glUniform4f(glGetUniformLocation(program_, "u_rect"), x0, y0, x1, y1);
    glUniform1i(glGetUniformLocation(program_, "u_image"), 0);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, texture_);
    glBindVertexArray(vao_);
    glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
    glBindVertexArray(0);
    glDisable(GL_BLEND);
  }

 private:
  GLuint program_ = 0, vao_ = 0, texture_ = 0;
  int width_ = 0, height_ = 0;
};

// Marker dots with a colour per dot (the renderer's MeshDrawer draws one colour for all): round
// points of `kMarkerPx` pixels with a dark rim, depth-tested against the mesh just drawn into the
// bound framebuffer, like the picture sheet's dots.
constexpr float kMarkerPx = 9.0f;
// Colour of each TETRIG_SHM_MARKER_* state: unknown grey, measured green, predicted (occluded)
// red-orange, blended (returning) yellow, rejected (implausible sample) magenta.
constexpr unsigned kMarkerStates = 5;
constexpr float kMarkerRgb[kMarkerStates][3] = {
    {0.62f, 0.62f, 0.66f}, {0.20f, 0.85f, 0.30f}, {1.00f, 0.30f, 0.10f}, {1.00f, 0.85f, 0.10f}, {0.90f, 0.20f, 0.90f}};

class MarkerDots {
 public:
  MarkerDots() {
    const char* vs = R"(#version 330 core
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_color;
uniform mat4 u_view;
uniform mat4 u_projection;
uniform float u_size;
out vec3 v_color;
void main() {
  gl_Position = u_projection * (u_view * vec4(a_position, 1.0));
  gl_PointSize = u_size;
  v_color = a_color;
}
)";
    const char* fs = R"(#version 330 core
in vec3 v_color;
out vec4 o_color;
void main() {
  vec2 d = gl_PointCoord - vec2(0.5);
  float r2 = dot(d, d);
  if (r2 > 0.25) discard;
  o_color = vec4(v_color * (r2 > 0.12 ? 0.55 : 1.0), 1.0);
}
)";
    program_ = render::linkProgram(vs, fs, "viewer marker");
    glGenVertexArrays(1, &vao_);
    glGenBuffers(1, &vbo_);
    glBindVertexArray(vao_);
    glBindBuffer(GL_ARRAY_BUFFER, vbo_);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float), nullptr);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float), reinterpret_cast<const void*>(3 * sizeof(float)));
    glEnableVertexAttribArray(1);
    glBindVertexArray(0);
  }
  MarkerDots(const MarkerDots&) = delete;
  MarkerDots& operator=(const MarkerDots&) = delete;
  ~MarkerDots() {
    glDeleteBuffers(1, &vbo_);
    glDeleteVertexArrays(1, &vao_);
    glDeleteProgram(program_);
  }
  // marker_count x 3 floats and marker_count states; a marker with a non-finite position is left
  // out, an unknown state byte is drawn as unknown.
  void set(std::span<const float> xyz, std::span<const std::uint8_t> states) {
    data_.clear();
    for (std::size_t k = 0; k < states.size() && 3 * k + 2 < xyz.size(); ++k) {
      const float* p = &xyz[3 * k];
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) continue;
      const float* c = kMarkerRgb[states[k] < kMarkerStates ? states[k] : 0];
      data_.insert(data_.end(), {p[0], p[1], p[2], c[0], c[1], c[2]});
    }
    glBindBuffer(GL_ARRAY_BUFFER, vbo_);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(data_.size() * sizeof(float)), data_.data(), GL_DYNAMIC_DRAW);
    count_ = static_cast<GLsizei>(data_.size() / 6);
  }
  // Over the mesh just drawn (its depth buffer) in the bound framebuffer of `width` x `height`.
  void draw(const render::OrbitCamera& camera, int width, int height) const {
    if (count_ == 0) return;
    const float aspect = static_cast<float>(width) / static_cast<float>(std::max(height, 1));
    const Eigen::Matrix4f view = camera.view(aspect), projection = camera.projection(aspect);
    glViewport(0, 0, width, height);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LEQUAL);
    glDisable(GL_BLEND);
    glEnable(GL_PROGRAM_POINT_SIZE);
    glUseProgram(program_);
    glUniformMatrix4fv(glGetUniformLocation(program_, "u_view"), 1, GL_FALSE, view.data());
    glUniformMatrix4fv(glGetUniformLocation(program_, "u_projection"), 1, GL_FALSE, projection.data());
    glUniform1f(glGetUniformLocation(program_, "u_size"), kMarkerPx);
    glBindVertexArray(vao_);
    glDrawArrays(GL_POINTS, 0, count_);
    glBindVertexArray(0);
    glUseProgram(0);
    glDepthFunc(GL_LESS);
  }

 private:
  GLuint program_ = 0, vao_ = 0, vbo_ = 0;
  GLsizei count_ = 0;
  std::vector<float> data_;  // per dot: x y z r g b
};

struct Input {
  bool dragging = false;
  double last_x = 0, last_y = 0;
  double drag_dx = 0, drag_dy = 0, scroll = 0;
  bool reset = false, toggle_markers = false, toggle_follow = false, refresh = false;
};

struct GlfwSession {
  GlfwSession() {
    glfwSetErrorCallback([](int, const char* description) { g_glfw_error = description ? description : "unknown GLFW error"; });
    if (!glfwInit()) {
      throw std::runtime_error("cannot open a window (GLFW: " + g_glfw_error +
                               "); without a display run it headless: xvfb-run -a tetrig view ... (Debian: xvfb xauth)");
    }
  }
  // No glfwTerminate(): it unloads the GL driver, whose few unreleased blocks LeakSanitizer then
  // reports from an unknown module (ASan builds fail on them); runView ends the process anyway,
  // and a second runView in one process finds GLFW initialized.
  ~GlfwSession() = default;
};

// Latency and rate figures over the frames of the last refresh period.
struct Window {
  std::uint64_t first_id = 0, last_id = 0;
  std::int64_t first_pub = 0, last_pub = 0;
  double recv_pub_sum = 0, pub_seen_sum = 0, recv_seen_sum = 0;
  int recv_count = 0, seen_count = 0, frames = 0;
};

class Viewer {
 public:
  explicit Viewer(const ViewOptions& o) : o_(o), name_(segmentName(o.name)) {
    if (o.after_frames < 1) throw std::invalid_argument("--after-frames must be at least 1");
    if (!(o.timeout_s > 0.0) || o.timeout_s > 86400.0) throw std::invalid_argument("--timeout must be in (0, 86400] seconds");
    if (o.width < 64 || o.height < 64 || o.width > 8192 || o.height > 8192) throw std::invalid_argument("--size must be within 64..8192 pixels");
    if (o.up != "x" && o.up != "y" && o.up != "z") throw std::invalid_argument("--up must be x, y or z");
    up_axis_ = o.up[0] - 'x';
    if (!o.screenshot.empty()) {
      const std::filesystem::path p(o.screenshot);
      std::string ext = p.extension().string();
      std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
      if (ext != ".png") throw std::invalid_argument("--screenshot must name a .png file (got '" + printable(o.screenshot.c_str()) + "')");
      std::error_code ec;
      const std::filesystem::path dir = p.has_parent_path() ? p.parent_path() : std::filesystem::path(".");
      if (!std::filesystem::is_directory(dir, ec)) {
        throw std::invalid_argument("--screenshot: directory " + dir.string() + " does not exist");
      }
    }
    show_markers_ = o.markers;
    follow_ = o.follow;
    if (o.dds) {
#if TETRIG_HAVE_DDS
      try {
        const std::string base = dds::topicBaseName(o.name);
        name_ = dds::frameTopicName(base);
        dds_ = std::make_unique<dds::FrameSubscriber>(base, dds::DdsOptions{});
      } catch (const dds::DdsError& e) {
        throw std::runtime_error(std::string("--dds: ") + e.what());
      }
#else
      throw std::invalid_argument("--dds: this build has no DDS (install cyclonedds-dev and cyclonedds-tools, configure with -DTETRIG_DDS=ON)");
#endif
    }
    const char* display = std::getenv("DISPLAY");
    const char* wayland = std::getenv("WAYLAND_DISPLAY");
    if ((display == nullptr || display[0] == '\0') && (wayland == nullptr || wayland[0] == '\0')) {
      throw std::runtime_error("no display (DISPLAY and WAYLAND_DISPLAY are not set): run it in a desktop session, or headless "
                               "with xvfb-run -a tetrig view " + name_ + " --screenshot FILE.png (Debian: xvfb xauth)");
    }
  }

  int run() {
    GlfwSession glfw;
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    glfwWindowHint(GLFW_SAMPLES, 0);  // multisampling happens in the offscreen target
    const std::string title = "tetrig view - " + name_;
    GLFWwindow* window = glfwCreateWindow(o_.width, o_.height, title.c_str(), nullptr, nullptr);
    if (window == nullptr) {
      throw std::runtime_error("cannot create an OpenGL 3.3 core window (GLFW: " + g_glfw_error +
                               "); needs Mesa (libgl1-mesa-dri) or a GPU driver; headless: xvfb-run -a");
    }
    std::unique_ptr<GLFWwindow, void (*)(GLFWwindow*)> window_guard(window, glfwDestroyWindow);
    glfwMakeContextCurrent(window);
    glfwSwapInterval(o_.screenshot.empty() ? 1 : 0);
    glfwSetWindowUserPointer(window, &input_);
    glfwSetMouseButtonCallback(window, [](GLFWwindow* w, int button, int action, int) {
      auto* in = static_cast<Input*>(glfwGetWindowUserPointer(w));
      if (button == GLFW_MOUSE_BUTTON_LEFT) {
        in->dragging = action == GLFW_PRESS;
        glfwGetCursorPos(w, &in->last_x, &in->last_y);
      }
    });
    glfwSetCursorPosCallback(window, [](GLFWwindow* w, double x, double y) {
      auto* in = static_cast<Input*>(glfwGetWindowUserPointer(w));
      if (in->dragging) {
        in->drag_dx += x - in->last_x;
        in->drag_dy += y - in->last_y;
      }
      in->last_x = x;
      in->last_y = y;
    });
    glfwSetScrollCallback(window, [](GLFWwindow* w, double, double dy) { static_cast<Input*>(glfwGetWindowUserPointer(w))->scroll += dy; });
    glfwSetWindowRefreshCallback(window, [](GLFWwindow* w) { static_cast<Input*>(glfwGetWindowUserPointer(w))->refresh = true; });
    glfwSetKeyCallback(window, [](GLFWwindow* w, int key, int, int action, int) {
      if (action != GLFW_PRESS) return;
      auto* in = static_cast<Input*>(glfwGetWindowUserPointer(w));
      if (key == GLFW_KEY_R) in->reset = true;
      if (key == GLFW_KEY_M) in->toggle_markers = true;
      if (key == GLFW_KEY_F) in->toggle_follow = true;
      if (key == GLFW_KEY_ESCAPE || key == GLFW_KEY_Q) glfwSetWindowShouldClose(w, GLFW_TRUE);
    });

    int result = 0;
    try {
      result = loop(window);
    } catch (...) {
      closeReader();
      drawer_.reset();
      dots_.reset();
      overlay_.reset();
      target_.reset();
      throw;
    }
    closeReader();
    drawer_.reset();
    dots_.reset();
    overlay_.reset();
    target_.reset();
    return result;
  }

 private:
  using Clock = std::chrono::steady_clock;

  void status(const std::string& line) {
    status_ = line;
    if (!o_.quiet) std::fprintf(stderr, "tetrig view: %s\n", line.c_str());
    overlay_dirty_ = true;
  }

  void closeReader() {
    if (open_) tetrig_shm_close(&reader_);
    open_ = false;
  }

  // Opens the segment when a producer is there; throws when it exists but cannot be used.
  void tryOpen() {
#if TETRIG_HAVE_DDS
    if (dds_) {
      pollDds();  // the static data of a (new) publisher opens it
      return;
    }
#endif
    const int rc = tetrig_shm_open(&reader_, name_.c_str());
    if (rc == TETRIG_SHM_E_NOT_FOUND || rc == TETRIG_SHM_E_NOT_READY) return;
    if (rc != TETRIG_SHM_OK) {
      std::string why = tetrig_shm_status_string(rc);
      if (rc == TETRIG_SHM_E_ACCESS || rc == TETRIG_SHM_E_SYSTEM) why += std::string(": ") + std::strerror(reader_.error);
      if (rc == TETRIG_SHM_E_OWNER) {
        why += format(" (uid %lu; tetrig view reads only segments of its own user, uid %lu)", static_cast<unsigned long>(reader_.owner_uid),
                      static_cast<unsigned long>(geteuid()));
      }
      if (rc == TETRIG_SHM_E_MODE) why += format(" (mode %04lo)", static_cast<unsigned long>(reader_.mode));
      throw std::runtime_error("cannot use segment " + name_ + ": " + why);
    }
    if (instances_ > 0 && reader_.instance_id == instance_id_) {  // the same dead or stopped segment: no new producer yet
      tetrig_shm_close(&reader_);
      return;
    }
    open_ = true;
    const std::uint32_t vertices = tetrig_shm_vertex_count(&reader_);
    const std::uint32_t triangle_count = tetrig_shm_triangle_count(&reader_);
    std::vector<std::uint32_t> triangles(std::size_t{triangle_count} * 3, 0u);
    if (tetrig_shm_copy_triangles(&reader_, triangles.data(), triangles.size()) != TETRIG_SHM_OK) {  // the copy is checked
      closeReader();
      throw std::runtime_error("cannot use segment " + name_ + ": its triangles were rewritten after it was opened");
    }
    char rig_name[256];
    tetrig_shm_copy_rig_name(&reader_, rig_name, sizeof rig_name);
    adoptRig(vertices, std::move(triangles), tetrig_shm_rest_positions(&reader_), rig_name, reader_.instance_id, reader_.producer_pid,
             tetrig_shm_marker_count(&reader_), tetrig_shm_has_marker_positions(&reader_) != 0);
  }

  // A producer's static data (from the segment or DDS): the mesh to draw, the overlay's names.
  void adoptRig(std::uint32_t vertices, std::vector<std::uint32_t> triangles, const float* rest, const char* rig_name,
                std::uint64_t instance_id, std::int32_t pid, std::uint32_t marker_count, bool has_marker_positions) {
    const std::uint32_t triangle_count = static_cast<std::uint32_t>(triangles.size() / 3);
    triangles_ = std::move(triangles);
    positions_.assign(std::size_t{vertices} * 3, 0.0f);
    const bool same_rig = drawer_ && drawer_->vertexCount() == static_cast<std::int32_t>(vertices) && triangles_ == drawn_triangles_;
    if (!same_rig) {
      std::vector<std::int32_t> t(triangles_.begin(), triangles_.end());
      drawer_ = std::make_unique<render::MeshDrawer>(t, static_cast<std::int32_t>(vertices));
      drawn_triangles_ = triangles_;
      rest_bounds_ = render::Bounds{};
      rest_bounds_.add(std::span<const float>(rest, std::size_t{vertices} * 3));
      drawer_->setFloor(rest_bounds_, up_axis_);
      drawer_->setPositions(std::span<const float>(rest, std::size_t{vertices} * 3));
      camera_ = home();
      have_frame_ = false;
    }
    rig_name_ = printable(rig_name);
    if (instances_ > 0) {
      status(format("producer restarted: instance %016" PRIx64 " (pid %ld) -> %016" PRIx64 " (pid %ld)", instance_id_, static_cast<long>(pid_),
                    instance_id, static_cast<long>(pid)));
    } else {
      status(format("%s: rig '%s', %u vertices, %u triangles, %s", name_.c_str(), rig_name_.c_str(), vertices, triangle_count,
                    pid > 0 ? format("pid %ld", static_cast<long>(pid)).c_str() : "over DDS"));
    }
    open_ = true;
    ++instances_;
    instance_id_ = instance_id;
    pid_ = pid;
    last_id_ = 0;
    producer_note_.clear();
    marker_count_ = marker_count;
    has_marker_positions_ = has_marker_positions;
    marker_positions_.assign(has_marker_positions_ ? std::size_t{marker_count_} * 3 : 0, 0.0f);
    marker_states_.assign(has_marker_positions_ ? marker_count_ : 0u, std::uint8_t{TETRIG_SHM_MARKER_UNKNOWN});
    std::fill(std::begin(state_counts_), std::end(state_counts_), 0u);
    if (dots_) dots_->set({}, {});
  }

  render::OrbitCamera home() const { return render::OrbitCamera::framing(rest_bounds_, up_axis_, 30.0f, 12.0f); }

  // Takes the newest frame if there is one; returns true when a new frame was taken.
  bool takeFrame() {
#if TETRIG_HAVE_DDS
    if (dds_) return pollDds();
#endif
    if (tetrig_shm_latest_frame_id(&reader_) <= last_id_) return false;
    TetrigShmFrameInfo info;
    // With the marker block: the mesh and the markers of one frame, in one read.
    const int rc = has_marker_positions_
                       ? tetrig_shm_read_latest_markers(&reader_, positions_.data(), positions_.size(), nullptr, 0, marker_positions_.data(),
                                                        marker_positions_.size(), marker_states_.data(), marker_states_.size(), &info)
                       : tetrig_shm_read_latest(&reader_, positions_.data(), positions_.size(), nullptr, 0, &info);
    if (rc != TETRIG_SHM_OK) return false;
    if (info.frame_id <= last_id_) return false;
    if (has_marker_positions_) {
      std::fill(std::begin(state_counts_), std::end(state_counts_), 0u);
      for (const std::uint8_t st : marker_states_) ++state_counts_[st < kMarkerStates ? st : 0];
      if (dots_) dots_->set(marker_positions_, marker_states_);
    }
    noteFrame(info, tetrig_shm_now_ns());
    return true;
  }

  // A new frame is in positions_ (and the marker arrays): draw it and count its figures.
  void noteFrame(const TetrigShmFrameInfo& info, std::int64_t seen) {
    last_id_ = info.frame_id;
    info_ = info;
    drawer_->setPositions(positions_);
    if (follow_) {
      render::Bounds b;
      b.add(positions_);
      if (!b.empty()) camera_.target = b.center();
    }
    have_frame_ = true;
    ++frames_taken_;
    if (stats_.frames == 0) {
      stats_.first_id = info.frame_id;
      stats_.first_pub = info.publish_ns;
    }
    stats_.last_id = info.frame_id;
    stats_.last_pub = info.publish_ns;
    ++stats_.frames;
    const std::int64_t recv_pub = tetrig_shm_receive_to_publish_ns(&info);
    const std::int64_t pub_seen = tetrig_shm_publish_age_ns(&info, seen);
    const std::int64_t recv_seen = tetrig_shm_interval_ns(info.receive_ns, seen);
    if (recv_pub >= 0) {
      stats_.recv_pub_sum += static_cast<double>(recv_pub) * 1e-6;
      stats_.recv_seen_sum += static_cast<double>(recv_seen) * 1e-6;
      ++stats_.recv_count;
    }
    if (pub_seen >= 0) {
      stats_.pub_seen_sum += static_cast<double>(pub_seen) * 1e-6;
      ++stats_.seen_count;
    }
    if (!producer_note_.empty()) {
      producer_note_.clear();
      overlay_dirty_ = true;
    }
  }

#if TETRIG_HAVE_DDS
  // Takes every pending DDS event: static data of a new publisher (adoptRig), its liveliness (the
  // overlay's note), frames (checked; the newest accepted one of the current publisher is drawn).
  // Returns true when a new frame was taken.
  bool pollDds() {
    dds_events_.clear();
    dds_->poll(0, dds_events_);
    const dds::ReceivedFrame* newest = nullptr;
    for (const dds::SubscriberEvent& e : dds_events_) {
      std::string why;
      if (e.kind == dds::SubscriberEvent::kStatic) {
        if (!dds_checker_.acceptStatic(e.static_data, why)) {
          status(why);
        } else if (instances_ == 0 || e.static_data.instance_id != instance_id_) {
          std::vector<std::uint32_t> triangles = e.static_data.triangles;
          adoptRig(e.static_data.vertex_count, std::move(triangles), e.static_data.rest_positions.data(), e.static_data.rig_name.c_str(),
                   e.static_data.instance_id, 0, static_cast<std::uint32_t>(e.static_data.marker_labels.size()),
                   !e.static_data.marker_labels.empty());
          newest = nullptr;  // frames before it belong to the previous publisher
        }
      } else if (e.kind == dds::SubscriberEvent::kFrame) {
        const auto verdict = dds_checker_.checkFrame(e.frame, why);
        if (verdict == dds::FrameChecker::Verdict::kRefused) {
          status(why);
        } else if (verdict == dds::FrameChecker::Verdict::kAccepted && open_ && e.frame.instance_id == instance_id_) {
          newest = &e.frame;
        }
      } else {
        const std::string note = e.kind == dds::SubscriberEvent::kPublisherAlive ? std::string()
                                 : e.kind == dds::SubscriberEvent::kPublisherLost
                                     ? "publisher lost (its liveliness lease passed): last frame kept, waiting for a new one"
                                     : "publisher stopped: last frame kept, waiting for a new one";
        if (note != producer_note_) {
          producer_note_ = note;
          if (!note.empty()) status(note);
          overlay_dirty_ = true;
        }
      }
    }
    if (newest == nullptr) return false;
    const dds::ReceivedFrame& f = *newest;
    std::copy(f.positions.begin(), f.positions.end(), positions_.begin());  // the checker matched the sizes
    const bool markers = has_marker_positions_ && f.marker_positions.size() == marker_positions_.size() &&
                         f.marker_states.size() == marker_states_.size();
    if (markers) {
      std::copy(f.marker_positions.begin(), f.marker_positions.end(), marker_positions_.begin());
      std::copy(f.marker_states.begin(), f.marker_states.end(), marker_states_.begin());
      std::fill(std::begin(state_counts_), std::end(state_counts_), 0u);
      for (const std::uint8_t st : marker_states_) ++state_counts_[st < kMarkerStates ? st : 0];
      if (dots_) dots_->set(marker_positions_, marker_states_);
    }
    TetrigShmFrameInfo info{};
    info.frame_id = f.frame_id;
    info.source_frame = f.source_frame;
    info.iterations = f.iterations;
    info.flags = f.flags;
    info.occluded_markers = f.occluded_markers;
    info.device_ns = f.device_ns;
    info.receive_ns = f.receive_ns;
    info.publish_ns = f.publish_ns;
    noteFrame(info, f.seen_ns);
    return true;
  }
#endif

  // No new frame for a while: what is the producer doing?
  void checkProducer() {
    if (o_.dds) return;  // DDS: the liveliness events of pollDds
    const int st = tetrig_shm_producer_status(&reader_, static_cast<std::int64_t>(o_.stale_ms * 1e6));
    const long age_ms = static_cast<long>(tetrig_shm_heartbeat_age_ns(&reader_, tetrig_shm_now_ns()) / 1000000);
    std::string note;
    if (st == TETRIG_SHM_PRODUCER_ALIVE) {
      if (tetrig_shm_state(&reader_) == TETRIG_SHM_STATE_STALE_SOURCE) note = "source silent: the producer holds the pose";
    } else if (st == TETRIG_SHM_PRODUCER_STALE) {
      note = format("producer pid %ld not responding (heartbeat %ld ms old)", static_cast<long>(pid_), age_ms);
    } else {
      if (tetrig_shm_name_status(&reader_) == TETRIG_SHM_NAME_REPLACED) {
        closeReader();  // the loop opens the new segment and reports the restart
        return;
      }
      note = st == TETRIG_SHM_PRODUCER_STOPPED ? format("producer stopped (pid %ld): last frame kept, waiting for a new one", static_cast<long>(pid_))
                                               : format("producer pid %ld died: last frame kept, waiting for a new one", static_cast<long>(pid_));
      // Its segment is gone or dead: keep the picture, drop the mapping, wait for the name to come back.
      closeReader();
    }
    if (note != producer_note_) {
      producer_note_ = note;
      if (!note.empty()) status(note);
      overlay_dirty_ = true;
    }
  }

  // Every half second; sooner the first time (a few frames suffice) and before a screenshot.
  void refreshFigures(Clock::time_point now, bool force = false) {
    const double dt = std::chrono::duration<double>(now - window_start_).count();
    const bool early = (force || !figures_valid_) && stats_.frames >= 3 && dt > 0.02;
    if (dt < 0.5 && !early) return;
    figures_valid_ = figures_valid_ || stats_.frames >= 2;
    if (stats_.frames >= 2 && stats_.last_pub > stats_.first_pub) {
      rate_hz_ = static_cast<double>(stats_.last_id - stats_.first_id) / (static_cast<double>(stats_.last_pub - stats_.first_pub) * 1e-9);
    } else if (stats_.frames == 0) {
      rate_hz_ = 0;
    }
    if (stats_.recv_count > 0) {
      recv_pub_ms_ = stats_.recv_pub_sum / stats_.recv_count;
      recv_seen_ms_ = stats_.recv_seen_sum / stats_.recv_count;
    }
    if (stats_.seen_count > 0) pub_seen_ms_ = stats_.pub_seen_sum / stats_.seen_count;
    fps_ = static_cast<double>(draws_) / dt;
    draws_ = 0;
    stats_ = {};
    window_start_ = now;
    overlay_dirty_ = true;
  }

  void buildOverlay(int fb_width) {
    std::vector<std::string> lines;
    lines.push_back("tetrig view  " + name_ + (instances_ > 0 ? "  rig '" + rig_name_ + "'" : std::string()));
    if (have_frame_) {
      lines.push_back(format("frame %" PRIu64 "  source %" PRIu64 "  iter %d  occluded %u", info_.frame_id, info_.source_frame,
                             static_cast<int>(info_.iterations), static_cast<unsigned>(info_.occluded_markers)) +
                      (info_.flags != 0 ? "  (" + frameFlagText(info_.flags) + ")" : std::string()));
      lines.push_back(format("producer %.1f Hz  drawn %.0f fps  recv->pub %.0f us  pub->seen %.0f us  recv->seen %.0f us", rate_hz_, fps_,
                             1e3 * recv_pub_ms_, 1e3 * pub_seen_ms_, 1e3 * recv_seen_ms_));
    }
    if (!open_ && instances_ == 0) lines.push_back("waiting for a producer of " + name_ + " ...");
    if (!producer_note_.empty()) lines.push_back(producer_note_);
    if (show_markers_ && instances_ > 0) {
      if (has_marker_positions_ && have_frame_) {
        lines.push_back(format("markers %u: measured %u  blended %u  predicted %u  rejected %u  unknown %u", marker_count_,
                               state_counts_[TETRIG_SHM_MARKER_MEASURED], state_counts_[TETRIG_SHM_MARKER_BLENDED],
                               state_counts_[TETRIG_SHM_MARKER_PREDICTED], state_counts_[TETRIG_SHM_MARKER_REJECTED],
                               state_counts_[TETRIG_SHM_MARKER_UNKNOWN]));
      } else {
        lines.push_back(format("markers: %u labelled, %u occluded this frame%s%s", marker_count_,
                               have_frame_ ? static_cast<unsigned>(info_.occluded_markers) : 0u,
                               have_frame_ && (info_.flags & TETRIG_SHM_FRAME_MARKERS_PREDICTED) ? ", some predicted" : "",
                               has_marker_positions_ ? ""
                               : marker_count_ == 0  ? " (the rig has no markers)"
                                                     : " (no marker positions: layout 1.0 producer, or left out)"));
      }
    }
    const int pad = 6;
    int width = 0;
    for (const std::string& l : lines) width = std::max(width, text_->width(l));
    overlay_image_.width = std::min(width + 2 * pad, fb_width);
    overlay_image_.height = static_cast<int>(lines.size()) * text_->lineHeight() + 2 * pad;
    overlay_image_.rgba.assign(static_cast<std::size_t>(overlay_image_.width) * static_cast<std::size_t>(overlay_image_.height) * 4, 0);
    for (std::size_t i = 0; i < overlay_image_.rgba.size(); i += 4) overlay_image_.rgba[i + 3] = 150;  // translucent black panel
    for (std::size_t k = 0; k < lines.size(); ++k) {
      text_->draw(overlay_image_, pad, pad + static_cast<int>(k) * text_->lineHeight(), lines[k], {235, 235, 235});
    }
    overlay_->upload(overlay_image_);
    overlay_dirty_ = false;
  }

  // Applies the input since the last call; true when the picture must be redrawn.
  bool applyInput() {
    const bool changed = input_.reset || input_.toggle_markers || input_.toggle_follow || input_.refresh || input_.drag_dx != 0 ||
                         input_.drag_dy != 0 || input_.scroll != 0;
    if (input_.reset) camera_ = home();
    if (input_.toggle_markers) {
      show_markers_ = !show_markers_;
      overlay_dirty_ = true;
    }
    camera_.azimuth_deg -= static_cast<float>(input_.drag_dx) * 0.4f;
    camera_.elevation_deg = std::clamp(camera_.elevation_deg + static_cast<float>(input_.drag_dy) * 0.4f, -89.0f, 89.0f);
    camera_.zoom = std::clamp(camera_.zoom * std::pow(0.9f, static_cast<float>(input_.scroll)), 0.05f, 20.0f);
    if (input_.toggle_follow) {
      follow_ = !follow_;
      if (!follow_) camera_.target = home().target;
    }
    input_.reset = input_.toggle_markers = input_.toggle_follow = input_.refresh = false;
    input_.drag_dx = input_.drag_dy = input_.scroll = 0;
    return changed;
  }

  int loop(GLFWwindow* window) {
    text_ = std::make_unique<render::TextRasterizer>(15);
    overlay_ = std::make_unique<OverlayQuad>();
    dots_ = std::make_unique<MarkerDots>();
    const auto start = Clock::now();
    auto next_open = start, next_check = start, next_redraw = start;
    window_start_ = start;
    status("waiting for a producer of " + name_ + " ...");
    while (!glfwWindowShouldClose(window)) {
      glfwPollEvents();
      const bool input_changed = applyInput();
      const auto now = Clock::now();
      bool got = false;
      if (!open_ && now >= next_open) {
        tryOpen();
        next_open = now + std::chrono::milliseconds(20);
      }
      if (open_) {
        got = takeFrame();
        if (!got && now >= next_check) {
          checkProducer();
          next_check = now + std::chrono::milliseconds(50);
        }
      }
      refreshFigures(now);
      int fw = 0, fh = 0;
      glfwGetFramebufferSize(window, &fw, &fh);
      if (fw < 1 || fh < 1) {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        continue;
      }
      const bool resized = !target_ || target_->width() != fw || target_->height() != fh;
      if (resized) target_ = std::make_unique<render::OffscreenTarget>(fw, fh);
      const bool shoot = !o_.screenshot.empty() && frames_taken_ >= static_cast<std::uint64_t>(o_.after_frames) && have_frame_;
      // Redraw only when something changed (a frame, input, the overlay, the window), and a few times a
      // second for the state lines: llvmpipe draws on the CPU the solver shares.
      if (!(got || input_changed || resized || overlay_dirty_ || shoot || now >= next_redraw)) {
        timeoutCheck(now, start);
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
        continue;
      }
      next_redraw = now + std::chrono::milliseconds(250);
      if (overlay_dirty_) buildOverlay(fw);
      target_->bind();
      if (drawer_) {
        drawScene(fw, fh);
      } else {
        glClearColor(render::kBackgroundBottom[0], render::kBackgroundBottom[1], render::kBackgroundBottom[2], 1.0f);
        glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
      }
      overlay_->draw(8, 8, fw, fh);
      ++draws_;
      if (shoot) {
        refreshFigures(Clock::now(), true);
        buildOverlay(fw);  // the figures as of this frame
        target_->bind();
        drawScene(fw, fh);
        overlay_->draw(8, 8, fw, fh);
        Image shot;
        shot.width = fw;
        shot.height = fh;
        shot.rgba.resize(static_cast<std::size_t>(fw) * static_cast<std::size_t>(fh) * 4);
        target_->readRgba(shot.rgba);
        for (std::size_t i = 3; i < shot.rgba.size(); i += 4) shot.rgba[i] = 255;
        render::writePng(o_.screenshot, shot);
        std::printf("tetrig view: screenshot %s (%d x %d): frame %" PRIu64 " of producer instance %016" PRIx64 " (%s), %" PRIu64
                    " frames taken\n",
                    o_.screenshot.c_str(), fw, fh, info_.frame_id, instance_id_,
                    pid_ > 0 ? format("pid %ld", static_cast<long>(pid_)).c_str() : "over DDS", frames_taken_);
        std::fflush(stdout);
        return 0;
      }
      target_->blitTo(0);
      glfwSwapBuffers(window);
      timeoutCheck(now, start);
      if (!got) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return 0;
  }

  // The mesh, then (--markers / M, with the segment's marker block and a frame) the marker dots.
  void drawScene(int fw, int fh) {
    drawer_->draw(camera_, fw, fh);
    if (show_markers_ && has_marker_positions_ && have_frame_) dots_->draw(camera_, fw, fh);
  }

  void timeoutCheck(Clock::time_point now, Clock::time_point start) const {
    if (o_.screenshot.empty() || now - start <= std::chrono::duration<double>(o_.timeout_s)) return;
    throw std::runtime_error(format("no screenshot: %" PRIu64 " of %d frames came from %s within %.1f s (%s)", frames_taken_, o_.after_frames,
                                    name_.c_str(), o_.timeout_s,
                                    instances_ == 0 ? "no producer appeared" : producer_note_.empty() ? "producer slow" : producer_note_.c_str()));
  }

  ViewOptions o_;
  std::string name_;
  int up_axis_ = 1;
  bool show_markers_ = false, follow_ = false;
  Input input_;
  TetrigShmReader reader_{};
  bool open_ = false;
  std::uint64_t instances_ = 0, instance_id_ = 0, last_id_ = 0, frames_taken_ = 0;
  std::int32_t pid_ = 0;
  std::uint32_t marker_count_ = 0;
  bool has_marker_positions_ = false;             // the segment carries the marker block (layout 1.1)
  std::vector<float> marker_positions_;           // the newest frame's markers (rig units, label order)
  std::vector<std::uint8_t> marker_states_;       // TETRIG_SHM_MARKER_* per marker
  unsigned state_counts_[kMarkerStates] = {0, 0, 0, 0, 0};       // markers per state in the newest frame
  std::string rig_name_, status_, producer_note_;
  std::vector<std::uint32_t> triangles_, drawn_triangles_;
  std::vector<float> positions_;
  TetrigShmFrameInfo info_{};
  bool have_frame_ = false;
  render::Bounds rest_bounds_;
  render::OrbitCamera camera_;
  std::unique_ptr<render::MeshDrawer> drawer_;
  std::unique_ptr<render::OffscreenTarget> target_;
  std::unique_ptr<render::TextRasterizer> text_;
  std::unique_ptr<OverlayQuad> overlay_;
  std::unique_ptr<MarkerDots> dots_;
#if TETRIG_HAVE_DDS
  std::unique_ptr<dds::FrameSubscriber> dds_;
  dds::FrameChecker dds_checker_;
  std::vector<dds::SubscriberEvent> dds_events_;
#endif
  Image overlay_image_;
  bool overlay_dirty_ = true;
  bool figures_valid_ = false;
  Window stats_;
  Clock::time_point window_start_;
  int draws_ = 0;
  double rate_hz_ = 0, fps_ = 0, recv_pub_ms_ = 0, pub_seen_ms_ = 0, recv_seen_ms_ = 0;
};

}  // namespace

std::string frameFlagText(std::uint32_t flags) {
  static constexpr std::pair<std::uint32_t, const char*> kNames[] = {
      {TETRIG_SHM_FRAME_STALE_SOURCE, "stale source"},        {TETRIG_SHM_FRAME_POSE_HELD, "pose held"},
      {TETRIG_SHM_FRAME_BUDGET_MISS, "budget miss"},          {TETRIG_SHM_FRAME_MARKERS_PREDICTED, "markers predicted"},
      {TETRIG_SHM_FRAME_INPUT_REJECTED, "input rejected"},    {TETRIG_SHM_FRAME_POSE_REJECTED, "pose rejected: last pose repeated"}};
  std::string text;
  const auto add = [&](const std::string& part) { text += (text.empty() ? "" : ", ") + part; };
  std::uint32_t known = 0;
  for (const auto& [bit, name] : kNames) {
    known |= bit;
    if (flags & bit) add(name);
  }
  if (const std::uint32_t other = flags & ~known; other != 0) add(format("flags 0x%x", static_cast<unsigned>(other)));
  return text;
}

int runView(const ViewOptions& options) {
  Viewer viewer(options);
  return viewer.run();
}

}  // namespace tetrig::tools
