# tetrig live: a Blender add-on that reads the tetrig shared-memory segment and updates a mesh
# object live, and imports a `tetrig export` (OBJ + PC2 through the Mesh Cache modifier).
#
# The segment (docs/shm.md, layout 1.x: any minor of major 1; the 1.1 marker block is not read; the
# C99 reader is runtime/include/tetrig_shm.h) is mapped read-only from /dev/shm/<name>. Its static data (rest positions, triangles, rig name) builds the
# mesh; each new frame is read with the segment's seqlock protocol: load latest_frame_id, load the
# slot's sequence word (odd: being written, retry), copy the frame info and positions, load the
# sequence again; a changed sequence or a frame id other than the one named means the writer
# lapped the copy: retry (at most 64 times). Memory order: the C reader uses acquire loads and an
# acquire fence; Python has neither, so this reader relies on x86-64's ordering of loads (total
# store order: loads are not reordered with other loads), on which the plain copies are exact. On
# other architectures (aarch64) a torn frame could in principle pass the check: the add-on warns.
#
# Mesh-local coordinates are the rig's coordinates, unchanged (rig units, the rig's axes); for a
# Y-up rig (the default of `tetrig build-rig`) the object is rotated +90 degrees about X so that the
# character stands on Blender's Z-up floor. Nothing else converts vertices, so what Blender holds
# is exactly what the producer published (or exported).
#
# Use (docs/blender.md): Edit > Preferences > Add-ons > Install... this file, enable "tetrig live";
# View3D > Sidebar > tetrig: segment name, Connect. File > Import > tetrig export (.pc2, .glb,
# .gltf). From a script: tetrig_live.connect("tetrig"), tetrig_live.poll_all() (what the timer
# calls), tetrig_live.import_export("/path/anim.pc2"), tetrig_live.import_gltf_export("anim.glb").
#
# NumPy (Debian python3-numpy) makes the copies fast (np.frombuffer + foreach_set); without it (or
# with TETRIG_LIVE_NUMPY=0 in the environment) the add-on copies through array.array('f') (slower,
# same values).

bl_info = {
    "name": "tetrig live",
    "author": "tetrig",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > tetrig; File > Import > tetrig export",
    "description": "Live mesh from a tetrig shared-memory segment; import tetrig exports (OBJ + PC2)",
    "category": "Animation",
}

import array
import json
import math
import mmap
import os
import platform
import re
import struct
import time

try:
    import numpy as np
except ImportError:  # Debian's blender works without python3-numpy
    np = None
if os.environ.get("TETRIG_LIVE_NUMPY") == "0":  # tests: the array.array path on a machine with numpy
    np = None

try:
    import bpy
    from bpy.props import BoolProperty, EnumProperty, FloatProperty, StringProperty
    from bpy_extras.io_utils import ImportHelper
except ImportError:  # the reader part also works outside Blender (tests, tools)
    bpy = None

# ---- segment layout 1.x, the 1.0 fields (docs/shm.md, runtime/include/tetrig_shm.h) -------------

MAGIC = 0x4D53474952544554  # bytes "TETRIGSM"
VERSION_MAJOR = 1
HEADER_SIZE = 256
ALIGNMENT = 64
MIN_SLOTS, MAX_SLOTS = 3, 64
SLOT_HEADER_SIZE = 128
SLOT_INFO_OFFSET = 16
HAS_NORMALS = 0x1
STATE_RUNNING, STATE_STALE_SOURCE, STATE_STOPPED = 1, 2, 3
STATE_NAMES = {0: "starting", STATE_RUNNING: "running", STATE_STALE_SOURCE: "source stale", STATE_STOPPED: "stopped"}

# TetrigShmFrameInfo (80 bytes)
FRAME_INFO = struct.Struct("<QQiIHHIqqqqqq")
FRAME_INFO_FIELDS = ("frame_id", "source_frame", "iterations", "flags", "occluded_markers", "reserved0", "reserved1",
                     "device_ns", "receive_ns", "taken_ns", "step_done_ns", "pose_done_ns", "publish_ns")
assert FRAME_INFO.size == 80


class SegmentError(Exception):
    """The segment cannot be used: message says what and what to do."""


class SegmentNotReady(SegmentError):
    """No segment of that name yet, or still being created: retry."""


def monotonic_ns():
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


def segment_path(name):
    """'/tetrig' or 'tetrig' -> /dev/shm/tetrig (POSIX shared memory on Linux)."""
    bare = name[1:] if name.startswith("/") else name
    if not bare or "/" in bare or len(bare) > 254:
        raise SegmentError("bad segment name %r: one name without '/', as given to tetrig run --publish" % name)
    return os.path.join("/dev/shm", bare)


def pid_alive(pid):
    """True when `pid` exists and is not a zombie (tetrig_shm_pid_alive)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    try:
        with open("/proc/%d/stat" % pid, "rb") as f:
            stat = f.read(512)
        paren = stat.rfind(b")")
        if paren >= 0 and stat[paren + 2:paren + 3] in (b"Z", b"X"):
            return False
    except FileNotFoundError:
        return False
    except OSError:
        pass
    return True


class Segment:
    """A read-only mapping of one segment with its header checked as tetrig_shm_attach checks it.

    Like tetrig_shm_open, it requires the segment to belong to `owner` (default: this process's
    effective uid) and not to be writable by group or others, copies every header field it uses
    once at open, checks the copies, and reads from the live header only latest_frame_id, state
    and heartbeat_ns (the slot index is latest_frame_id modulo the copied slot count)."""

    def __init__(self, name, owner=None):
        self.name = name
        self.path = segment_path(name)
        self.owner = os.geteuid() if owner is None else int(owner)
        try:
            fd = os.open(self.path, os.O_RDONLY | os.O_CLOEXEC)
        except FileNotFoundError:
            raise SegmentNotReady("no segment %s yet (is `tetrig run --publish %s` running?)" % (self.path, name.lstrip("/")))
        except PermissionError:
            raise SegmentError("%s: permission denied (segments are 0600: run Blender as the producer's user, "
                               "or start the producer with --shm-mode 644)" % self.path)
        try:
            st = os.fstat(fd)
            if st.st_uid != self.owner:
                raise SegmentError("%s belongs to uid %d, not %d: refused (another user could have taken the name; "
                                   "connect with owner=%d to accept it)" % (self.path, st.st_uid, self.owner, st.st_uid))
            if st.st_mode & 0o022:
                raise SegmentError("%s has mode %04o: group or others may write it, so it is refused (the producer "
                                   "must not widen write permission)" % (self.path, st.st_mode & 0o7777))
            if st.st_size < HEADER_SIZE:
                raise SegmentNotReady("%s is still being created" % self.path)
            self.mm = mmap.mmap(fd, st.st_size, mmap.MAP_SHARED, mmap.PROT_READ)
        finally:
            os.close(fd)
        self.device, self.inode, self.size = st.st_dev, st.st_ino, st.st_size
        self._words = None
        try:
            self._attach()
        except Exception:
            self.close()
            raise

    # -- header ---------------------------------------------------------------------------------
    def _u16(self, off):
        return struct.unpack_from("<H", self.mm, off)[0]

    def _u32(self, off):
        return struct.unpack_from("<I", self.mm, off)[0]

    def _u64(self, off):
        return struct.unpack_from("<Q", self.mm, off)[0]

    def _word(self, off):
        """One aligned 8-byte load (numpy: a single machine load; struct: a byte copy)."""
        if self._words is not None:
            return int(self._words[off // 8])
        return self._u64(off)

    def _range_ok(self, offset, nbytes):
        return offset % ALIGNMENT == 0 and HEADER_SIZE <= offset <= self.size and nbytes <= self.size - offset

    def _attach(self):
        bad = SegmentError
        magic = self._u64(0)
        if magic == 0:
            raise SegmentNotReady("%s is still being created" % self.path)
        if magic != MAGIC:
            raise bad("%s is not a tetrig segment (magic %#x); remove it if nothing uses it" % (self.path, magic))
        major, minor, header_size = self._u16(8), self._u16(10), self._u32(12)
        if major != VERSION_MAJOR:
            raise bad("%s has layout version %d.%d; this add-on reads %d.x: update the add-on" % (self.path, major, minor, VERSION_MAJOR))
        total = self._u64(16)
        if header_size < HEADER_SIZE or header_size % ALIGNMENT or total != self.size or total < header_size:
            raise bad("%s: header sizes do not match the file (%d bytes)" % (self.path, self.size))
        self.instance_id = self._u64(24)
        self.start_unix_ns = struct.unpack_from("<q", self.mm, 32)[0]
        self.producer_pid = struct.unpack_from("<i", self.mm, 48)[0]
        self.flags = self._u32(52)
        (self.vertex_count, self.triangle_count, self.slot_count, self.marker_count,
         rig_name_length) = struct.unpack_from("<5I", self.mm, 128)
        (self.triangles_offset, self.rest_offset, rig_name_offset, labels_offset, labels_size, self.slots_offset,
         self.slot_stride, self.slot_positions_offset, self.slot_normals_offset) = struct.unpack_from("<9Q", self.mm, 152)
        v = self.vertex_count
        if v == 0 or not MIN_SLOTS <= self.slot_count <= MAX_SLOTS:
            raise bad("%s: %d vertices, %d slots: not a usable segment" % (self.path, v, self.slot_count))
        if not (self._range_ok(self.triangles_offset, self.triangle_count * 12) and self._range_ok(self.rest_offset, v * 12) and
                self._range_ok(rig_name_offset, rig_name_length + 1) and self._range_ok(labels_offset, labels_size)):
            raise bad("%s: static data outside the file" % self.path)
        if self.mm[rig_name_offset + rig_name_length] != 0:
            raise bad("%s: rig name not terminated" % self.path)
        labels = bytes(self.mm[labels_offset:labels_offset + labels_size])
        if labels.count(b"\0") != self.marker_count or (labels_size and labels[-1] != 0):
            raise bad("%s: marker labels do not match the marker count" % self.path)
        if (self.slot_stride % ALIGNMENT or self.slot_positions_offset % ALIGNMENT or
                self.slot_positions_offset < SLOT_HEADER_SIZE or self.slot_positions_offset > self.slot_stride or
                v * 12 > self.slot_stride - self.slot_positions_offset):
            raise bad("%s: slot layout inconsistent" % self.path)
        if self.flags & HAS_NORMALS:
            n = self.slot_normals_offset
            if n % ALIGNMENT or n < SLOT_HEADER_SIZE or n > self.slot_stride or v * 12 > self.slot_stride - n or \
                    not (self.slot_positions_offset + v * 12 <= n or n + v * 12 <= self.slot_positions_offset):
                raise bad("%s: normals layout inconsistent" % self.path)
        elif self.slot_normals_offset != 0:
            raise bad("%s: normals offset without normals" % self.path)
        if self.slot_stride == 0 or self.slot_stride > self.size // self.slot_count or \
                not self._range_ok(self.slots_offset, self.slot_stride * self.slot_count):
            raise bad("%s: slots outside the file" % self.path)
        self.rig_name = bytes(self.mm[rig_name_offset:rig_name_offset + rig_name_length]).decode("utf-8", "replace")
        self.marker_labels = [s.decode("utf-8", "replace") for s in labels.split(b"\0")[:self.marker_count]]
        self.triangles = self._array("I", self.triangles_offset, self.triangle_count * 3)
        if any(i >= v for i in self.triangles):
            raise bad("%s: a triangle index is out of range" % self.path)
        self.rest_positions = self._array("f", self.rest_offset, v * 3)
        if np is not None:
            self._words = np.frombuffer(self.mm, dtype="<u8", count=self.size // 8)
        self.max_attempts = 64
        self.last_frame_id = 0
        self.reads = self.retries = self.busy = 0

    def _array(self, typecode, offset, count):
        """A copy of `count` little-endian items at `offset` (numpy array, or array.array)."""
        if np is not None:
            return np.frombuffer(self.mm, dtype="<u4" if typecode == "I" else "<f4", count=count, offset=offset).copy()
        a = array.array(typecode)
        a.frombytes(self.mm[offset:offset + 4 * count])
        return a

    def new_positions_buffer(self):
        return np.empty(self.vertex_count * 3, dtype=np.float32) if np is not None else array.array("f", bytes(12 * self.vertex_count))

    # -- live words -----------------------------------------------------------------------------
    def latest_frame_id(self):
        return self._word(80)

    def state(self):
        return self._u32(64)

    def heartbeat_ns(self):
        return struct.unpack_from("<q", self.mm, 72)[0]

    def read_latest(self, positions):
        """Copies the newest complete frame into `positions` (new_positions_buffer()); returns its
        info as a dict, None when no frame was published yet. Raises SegmentError after
        max_attempts lapped copies (call again)."""
        nbytes = self.vertex_count * 12
        for _ in range(self.max_attempts):
            latest = self._word(80)
            if latest == 0:
                return None
            slot = self.slots_offset + ((latest - 1) % self.slot_count) * self.slot_stride
            seq1 = self._word(slot)
            if seq1 & 1:
                self.retries += 1
                continue
            info = FRAME_INFO.unpack_from(self.mm, slot + SLOT_INFO_OFFSET)
            start = slot + self.slot_positions_offset
            if np is not None:
                positions[:] = np.frombuffer(self.mm, dtype="<f4", count=self.vertex_count * 3, offset=start)
            else:
                positions[:] = array.array("f", self.mm[start:start + nbytes])
            seq2 = self._word(slot)
            if seq1 != seq2 or info[0] != latest:
                self.retries += 1
                continue
            self.last_frame_id = latest
            self.reads += 1
            return dict(zip(FRAME_INFO_FIELDS, info))
        self.busy += 1
        raise SegmentError("the writer lapped every copy (%d attempts)" % self.max_attempts)

    def producer_status(self, stale_after_ns=1_000_000_000):
        """'stopped', 'dead', 'stale' or 'alive' (tetrig_shm_producer_status)."""
        if self.state() == STATE_STOPPED:
            return "stopped"
        if not pid_alive(self.producer_pid):
            return "dead"
        if monotonic_ns() - self.heartbeat_ns() > stale_after_ns:
            return "stale"
        return "alive"

    def name_status(self):
        """'same', 'replaced' (a new producer: open again) or 'gone' (tetrig_shm_name_status)."""
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            return "gone"
        return "same" if (st.st_dev, st.st_ino) == (self.device, self.inode) else "replaced"

    def close(self):
        self._words = None
        if getattr(self, "mm", None) is not None:
            self.mm.close()
            self.mm = None


# ---- Blender: the live link ---------------------------------------------------------------------

UP_AXES = {"Y": (math.pi / 2, 0.0, 0.0), "Z": (0.0, 0.0, 0.0), "-Y": (-math.pi / 2, 0.0, 0.0)}

_links = {}  # segment name -> LiveLink
_timer_interval = 1.0 / 240.0


def _ensure_object(name, segment, up):
    """The mesh object `name`, (re)built from the segment's rest pose and triangles when missing or
    when its vertex count differs."""
    obj = bpy.data.objects.get(name)
    if obj is not None and (obj.type != "MESH" or len(obj.data.vertices) != segment.vertex_count):
        mesh = obj.data if obj.type == "MESH" else None
        bpy.data.objects.remove(obj)
        if mesh is not None and mesh.users == 0:
            bpy.data.meshes.remove(mesh)
        obj = None
    if obj is None:
        mesh = bpy.data.meshes.new(name)
        n, t = segment.vertex_count, segment.triangle_count
        mesh.vertices.add(n)
        mesh.vertices.foreach_set("co", segment.rest_positions)
        mesh.loops.add(3 * t)
        mesh.loops.foreach_set("vertex_index", segment.triangles)
        mesh.polygons.add(t)
        if np is not None:
            mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * t, 3, dtype=np.int32))
            mesh.polygons.foreach_set("loop_total", np.full(t, 3, dtype=np.int32))
        else:
            mesh.polygons.foreach_set("loop_start", array.array("i", range(0, 3 * t, 3)))
            mesh.polygons.foreach_set("loop_total", array.array("i", [3]) * t)
        mesh.update(calc_edges=True)
        mesh.validate()
        obj = bpy.data.objects.new(name, mesh)
        bpy.context.scene.collection.objects.link(obj)
        obj.rotation_euler = UP_AXES.get(up, UP_AXES["Y"])
    return obj


class LiveLink:
    """One segment driving one mesh object. poll() is what the timer calls."""

    def __init__(self, segment_name, object_name="", up="Y", owner=None):
        self.segment_name = segment_name
        self.object_name = object_name
        self.up = up
        self.owner = owner        # uid the segment must belong to (None: ours)
        self.segment = None
        self.positions = None
        self.frames = 0           # frames applied to the object
        self.last_info = None
        self.last_seen_ns = 0     # when the last frame was applied (CLOCK_MONOTONIC)
        self.status = "waiting for the segment"
        self.rate_hz = 0.0
        self._rate_t0, self._rate_n0 = monotonic_ns(), 0
        self._next_check_ns = 0
        self.instance_id = 0
        self.restarts = 0
        self.latency_us = None    # publish -> applied, of the last frame
        self._retry_ns = 0        # no attempt to open before this time (CLOCK_MONOTONIC)
        if platform.machine() not in ("x86_64", "AMD64", "i686", "i386"):
            print("tetrig live: warning: the Python seqlock reader relies on x86's load ordering; on %s a torn frame "
                  "could pass its check (docs/blender.md)" % platform.machine())

    def _open(self):
        now = monotonic_ns()
        if now < self._retry_ns:
            return False
        try:
            self.segment = Segment(self.segment_name, self.owner)
        except SegmentNotReady as e:
            self.status = str(e)
            self._retry_ns = now + 50_000_000
            return False
        except SegmentError:
            self._retry_ns = now + 1_000_000_000
            raise
        obj_name = self.object_name or self.segment.rig_name or "tetrig"
        self.object_name = obj_name
        _ensure_object(obj_name, self.segment, self.up)
        self.positions = self.segment.new_positions_buffer()
        if self.instance_id and self.segment.instance_id != self.instance_id:
            self.restarts += 1
        self.instance_id = self.segment.instance_id
        self.status = "connected to %s (pid %d)" % (self.segment.rig_name, self.segment.producer_pid)
        return True

    def close(self):
        if self.segment is not None:
            self.segment.close()
            self.segment = None

    def poll(self):
        """Applies the newest frame to the object if there is one; checks the producer now and
        then. Returns True when the object changed. Never raises for a missing or restarted
        producer (it reconnects); raises SegmentError for an unusable segment."""
        now = monotonic_ns()
        if self.segment is None and not self._open():
            return False
        seg = self.segment
        if seg.latest_frame_id() > seg.last_frame_id:
            info = seg.read_latest(self.positions)
            if info is not None:
                obj = bpy.data.objects.get(self.object_name)
                if obj is None or obj.type != "MESH" or len(obj.data.vertices) != seg.vertex_count:
                    obj = _ensure_object(self.object_name, seg, self.up)
                mesh = obj.data
                mesh.vertices.foreach_set("co", self.positions)
                mesh.update()
                self.frames += 1
                self.last_info = info
                self.last_seen_ns = monotonic_ns()
                self.latency_us = (self.last_seen_ns - info["publish_ns"]) / 1e3 if info["publish_ns"] > 0 else None
                self.status = "frame %d (%s)" % (info["frame_id"], STATE_NAMES.get(seg.state(), "?"))
                if now - self._rate_t0 >= 1_000_000_000:
                    self.rate_hz = (self.frames - self._rate_n0) * 1e9 / (now - self._rate_t0)
                    self._rate_t0, self._rate_n0 = now, self.frames
                return True
        if now >= self._next_check_ns:  # no new frame: is the producer still there?
            self._next_check_ns = now + 200_000_000
            name = seg.name_status()
            if name != "same":
                self.close()
                self.status = "producer restarted: reconnecting" if name == "replaced" else "segment removed: waiting for a producer"
                return False
            producer = seg.producer_status()
            if producer != "alive":
                self.status = "producer %s (last frame %d)" % (producer, seg.last_frame_id)
                self.rate_hz = 0.0
        return False


def connect(segment_name="tetrig", object_name="", up="Y", owner=None):
    """Starts (or restarts) the link of `segment_name`; the object appears with the first poll
    that finds the segment. `owner`: the uid the segment must belong to (default: Blender's own
    effective uid). Returns the LiveLink."""
    disconnect(segment_name)
    link = LiveLink(segment_name, object_name, up, owner)
    _links[segment_name] = link
    link.poll()
    if bpy is not None and not bpy.app.timers.is_registered(_timer):
        bpy.app.timers.register(_timer, first_interval=_timer_interval, persistent=True)
    return link


def disconnect(segment_name=None):
    for name in list(_links) if segment_name is None else [segment_name]:
        link = _links.pop(name, None)
        if link is not None:
            link.close()


def links():
    return dict(_links)


def poll_all():
    """Polls every link once (what the timer does); returns how many objects changed."""
    changed = 0
    for link in list(_links.values()):
        try:
            changed += 1 if link.poll() else 0
        except SegmentError as e:
            link.status = "error: %s" % e
            link.close()
    return changed


def _timer():
    if not _links:
        return None  # unregisters the timer
    if poll_all():
        for window in bpy.context.window_manager.windows if bpy.context.window_manager else []:
            for area in window.screen.areas:
                if area.type in ("VIEW_3D", "PROPERTIES"):
                    area.tag_redraw()
    return _timer_interval


# ---- Blender: importing an export (OBJ + PC2) ---------------------------------------------------

PC2_HEADER = struct.Struct("<12siiffi")


def read_pc2_header(path):
    """(points, start_frame, sample_rate, samples) of a PC2 file; ValueError for a file that is not one."""
    with open(path, "rb") as f:
        head = f.read(PC2_HEADER.size)
    if len(head) != PC2_HEADER.size:
        raise ValueError("%s: shorter than a PC2 header" % path)
    magic, version, points, start, rate, samples = PC2_HEADER.unpack(head)
    if magic != b"POINTCACHE2\0" or version != 1:
        raise ValueError("%s: not a PC2 point cache (POINTCACHE2, version 1)" % path)
    expected = PC2_HEADER.size + 12 * points * samples
    if os.path.getsize(path) != expected:
        raise ValueError("%s: %d bytes, the header announces %d" % (path, os.path.getsize(path), expected))
    return points, start, rate, samples


def read_export_keys(obj_path):
    """The 'tetrig-export key=value ...' comment of an exported OBJ (empty dict if absent)."""
    keys = {}
    with open(obj_path, "r", encoding="utf-8", errors="replace") as f:
        for line in f:
            if not line.startswith("#"):
                break
            m = re.match(r"#\s*tetrig-export\s+(.*)", line)
            if m:
                for item in m.group(1).split():
                    k, _, v = item.partition("=")
                    keys[k] = v
    return keys


def _import_obj(path):
    before = set(bpy.data.objects)
    if hasattr(bpy.ops.wm, "obj_import"):  # Blender 3.3+: the C++ importer; no axis change, vertex order kept
        bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
    else:
        bpy.ops.import_scene.obj(filepath=path, split_mode="OFF", axis_forward="Y", axis_up="Z")
    new = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
    if len(new) != 1:
        raise ValueError("%s: expected one mesh object from the OBJ, got %d" % (path, len(new)))
    return new[0]


def import_export(pc2_path, set_scene=True):
    """Imports FILE.rest.obj (the rest mesh; FILE.obj from exports before it had its own name)
    beside `pc2_path` and plays FILE.pc2 on it through a Mesh Cache modifier. Scene frame = clip
    frame (the modifier's frame_start = the PC2's start frame); with set_scene the scene's frame
    range and rate follow the export. Returns the object."""
    pc2_path = os.path.abspath(pc2_path)
    stem = os.path.splitext(pc2_path)[0]
    obj_path = stem + ".rest.obj"
    if not os.path.exists(obj_path) and os.path.exists(stem + ".obj") and read_export_keys(stem + ".obj"):
        obj_path = stem + ".obj"
    if not os.path.exists(obj_path):
        raise ValueError("%s: the rest mesh %s is missing (tetrig export writes it beside the .pc2)" % (pc2_path, obj_path))
    points, start, _rate, samples = read_pc2_header(pc2_path)
    keys = read_export_keys(obj_path)
    obj = _import_obj(obj_path)
    if len(obj.data.vertices) != points:
        raise ValueError("%s has %d vertices, the point cache %d points" % (obj_path, len(obj.data.vertices), points))
    obj.name = os.path.splitext(os.path.basename(pc2_path))[0]
    obj.rotation_euler = UP_AXES.get(keys.get("up", "y").upper(), UP_AXES["Y"])
    mod = obj.modifiers.new("tetrig export", "MESH_CACHE")
    mod.cache_format = "PC2"
    mod.filepath = pc2_path
    mod.frame_start = start
    mod.interpolation = "LINEAR"
    if set_scene:
        scene = bpy.context.scene
        scene.frame_start = int(round(start))
        scene.frame_end = int(round(start)) + samples - 1
        hz = float(keys.get("rate_hz", "0") or 0)
        if hz > 0:
            fps = max(1, int(round(hz)))
            scene.render.fps = fps
            scene.render.fps_base = fps / hz
    return obj


def read_gltf_info(path):
    """asset.extras.tetrig_export of a glTF/GLB that `tetrig export` wrote ({} for other files)."""
    with open(path, "rb") as f:
        head = f.read(20)
        if head[:4] == b"glTF":
            length, kind = struct.unpack_from("<II", head, 12)
            if kind != 0x4E4F534A:
                raise ValueError("%s: the first GLB chunk is not JSON" % path)
            doc = json.loads(f.read(length))
        else:
            f.seek(0)
            doc = json.loads(f.read())
    return doc.get("asset", {}).get("extras", {}).get("tetrig_export", {})


def import_gltf_export(path, set_scene=True):
    """Imports a glTF/GLB export with Blender's glTF importer: one object whose shape keys (one per
    frame) are animated. The importer turns seconds into frames at the scene's rate, so with
    set_scene the rate is set from the export first (one sample per scene frame, frame 0 = the
    first exported frame) and the frame range follows. Vertices come in glTF's Y-up converted to
    Blender's Z-up by the importer: (x, y, z) -> (x, -z, y). Returns the object."""
    info = read_gltf_info(path)
    scene = bpy.context.scene
    if set_scene and info.get("rate_hz", 0) > 0:
        fps = max(1, int(round(info["rate_hz"])))
        scene.render.fps = fps
        scene.render.fps_base = fps / info["rate_hz"]
    before = set(bpy.data.objects)
    # import_shading "NORMALS" (the default) fails in Debian's Blender 3.4.1 with NumPy >= 1.24
    # (np.bool); the export's normals are smooth vertex normals, which "SMOOTH" computes alike.
    bpy.ops.import_scene.gltf(filepath=path, import_shading="SMOOTH")
    new = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
    if len(new) != 1:
        raise ValueError("%s: expected one mesh object from the glTF, got %d" % (path, len(new)))
    if set_scene and info.get("frames", 0) > 0:
        scene.frame_start = 0
        scene.frame_end = int(info["frames"]) - 1
    return new[0]


if bpy is not None:

    class TETRIG_OT_connect(bpy.types.Operator):
        """Map a tetrig shared-memory segment and update a mesh object with every new frame"""
        bl_idname = "tetrig.connect"
        bl_label = "Connect"
        segment: StringProperty(name="Segment", default="tetrig", description="Name given to tetrig run --publish")
        object_name: StringProperty(name="Object", default="", description="Mesh object to drive (default: the rig's name)")
        up: EnumProperty(name="Up axis", items=[("Y", "Y", "Rig is Y-up (tetrig build-rig's default)"), ("Z", "Z", "Rig is Z-up"),
                                                ("-Y", "-Y", "Rig is -Y-up")], default="Y")

        def execute(self, context):
            try:
                link = connect(self.segment, self.object_name, self.up)
            except SegmentError as e:
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
            self.report({"INFO"}, "tetrig: %s" % link.status)
            return {"FINISHED"}

    class TETRIG_OT_disconnect(bpy.types.Operator):
        """Stop updating the object from the segment"""
        bl_idname = "tetrig.disconnect"
        bl_label = "Disconnect"
        segment: StringProperty(name="Segment", default="")

        def execute(self, context):
            disconnect(self.segment or None)
            return {"FINISHED"}

    class TETRIG_OT_import_export(bpy.types.Operator, ImportHelper):
        """Import a tetrig export: FILE.pc2 (the rest OBJ beside it, the point cache on a Mesh Cache
        modifier) or FILE.glb / FILE.gltf (Blender's glTF importer, scene rate from the export)"""
        bl_idname = "tetrig.import_export"
        bl_label = "Import tetrig export"
        filename_ext = ".pc2"
        filter_glob: StringProperty(default="*.pc2;*.glb;*.gltf", options={"HIDDEN"})
        set_scene: BoolProperty(name="Set scene frames and rate", default=True)

        def execute(self, context):
            try:
                if self.filepath.lower().endswith((".glb", ".gltf")):
                    obj = import_gltf_export(self.filepath, self.set_scene)
                else:
                    obj = import_export(self.filepath, self.set_scene)
            except (ValueError, OSError) as e:
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
            self.report({"INFO"}, "tetrig: imported %s" % obj.name)
            return {"FINISHED"}

    class TETRIG_PT_live(bpy.types.Panel):
        bl_label = "tetrig live"
        bl_space_type = "VIEW_3D"
        bl_region_type = "UI"
        bl_category = "tetrig"

        def draw(self, context):
            layout = self.layout
            settings = context.window_manager
            layout.prop(settings, "tetrig_segment")
            layout.prop(settings, "tetrig_up")
            row = layout.row()
            op = row.operator(TETRIG_OT_connect.bl_idname)
            op.segment = settings.tetrig_segment
            op.up = settings.tetrig_up
            row.operator(TETRIG_OT_disconnect.bl_idname).segment = settings.tetrig_segment
            for name, link in _links.items():
                box = layout.box()
                box.label(text="%s -> %s" % (name, link.object_name or "?"))
                box.label(text=link.status)
                if link.frames:
                    box.label(text="%.1f frames/s, %d frames" % (link.rate_hz, link.frames))
                if link.latency_us is not None:
                    box.label(text="publish -> shown %.0f us" % link.latency_us)

    def _menu_import(self, context):
        self.layout.operator(TETRIG_OT_import_export.bl_idname, text="tetrig export (.pc2 + .obj, .glb, .gltf)")

    _classes = (TETRIG_OT_connect, TETRIG_OT_disconnect, TETRIG_OT_import_export, TETRIG_PT_live)


def register():
    for c in _classes:
        bpy.utils.register_class(c)
    bpy.types.WindowManager.tetrig_segment = StringProperty(name="Segment", default="tetrig")
    bpy.types.WindowManager.tetrig_up = EnumProperty(name="Up axis", items=[("Y", "Y", ""), ("Z", "Z", ""), ("-Y", "-Y", "")], default="Y")
    bpy.types.TOPBAR_MT_file_import.append(_menu_import)


def unregister():
    disconnect()
    if bpy.app.timers.is_registered(_timer):
        bpy.app.timers.unregister(_timer)
    bpy.types.TOPBAR_MT_file_import.remove(_menu_import)
    del bpy.types.WindowManager.tetrig_up
    del bpy.types.WindowManager.tetrig_segment
    for c in reversed(_classes):
        bpy.utils.unregister_class(c)


if __name__ == "__main__":
    register()
