#!/usr/bin/env python3
"""`cmake --install` of this build into a fresh prefix, then an outside project built against it twice:
with its CMake package (find_package(tetrig CONFIG), tests/install/consumer/CMakeLists.txt) and with
its pkg-config files (cc/c++ and `pkg-config --cflags --libs`). Each build's programs (the C API from
C99, the C++ runtime and drivers, the device sources) run on the real rig and clip, and the last
frame's positions must equal the in-tree C99 test's (test_capi_c99) bit for bit.

usage: test_install.py BUILD_DIR SOURCE_DIR CMAKE C99_TEST RIG VERSION [FRAMES]
Exit 0: passed; 1: failed; 77: the install and both builds passed but the data to run them is absent.
"""
import os
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
import tetrig_test_data as data  # noqa: E402

failures = 0


def check(cond, what):
    global failures
    if not cond:
        failures += 1
        print(f"FAILED: {what}", flush=True)
    return cond


def run(cmd, env=None, cwd=None):
    """Runs a command; prints it and, when it fails, its output. Returns the CompletedProcess."""
    print("$ " + " ".join(cmd), flush=True)
    result = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd)
    if result.returncode != 0:
        print(result.stdout[-4000:] + result.stderr[-4000:], flush=True)
    return result


def main():
    build_dir, source_dir, cmake, c99_test, rig, version = sys.argv[1:7]
    frames = sys.argv[7] if len(sys.argv) > 7 else "240"
    consumer_src = os.path.join(source_dir, "tests", "install", "consumer")
    with tempfile.TemporaryDirectory(prefix="tetrig-install-") as tmp:
        prefix = os.path.join(tmp, "prefix")
        # 1. Install.
        if not check(run([cmake, "--install", build_dir, "--prefix", prefix]).returncode == 0, "cmake --install"):
            return 1
        libdir = next((d for d in ("lib", "lib64", os.path.join("lib", "x86_64-linux-gnu")) if os.path.isdir(os.path.join(prefix, d, "cmake", "tetrig"))), None)
        if not check(libdir is not None, "no <prefix>/lib*/cmake/tetrig"):
            return 1
        lib = os.path.join(prefix, libdir)
        for relative in ["include/tetrig.h", "include/tetrig_shm.h", "include/tetrig/version.h", "include/tetrig/live_rig.hpp",
                         "include/tetrig/drivers/c3d_playback.hpp", f"{libdir}/libtetrig.so", f"{libdir}/libtetrig_runtime.a",
                         f"{libdir}/libtetrig_drivers.a", f"{libdir}/cmake/tetrig/tetrigConfig.cmake",
                         f"{libdir}/cmake/tetrig/tetrigConfigVersion.cmake", f"{libdir}/cmake/tetrig/tetrigTargets.cmake",
                         f"{libdir}/pkgconfig/tetrig.pc", f"{libdir}/pkgconfig/tetrig-runtime.pc", f"{libdir}/pkgconfig/tetrig-drivers.pc",
                         "bin/tetrig", "bin/tetrig-shm-cat"]:
            check(os.path.exists(os.path.join(prefix, relative)), f"not installed: {relative}")
        with open(os.path.join(prefix, "include", "tetrig", "version.h")) as f:
            check(f'#define TETRIG_VERSION_STRING "{version}"' in f.read(), "tetrig/version.h does not hold the project's version")
        tool = run([os.path.join(prefix, "bin", "tetrig"), "--version"])
        check(tool.stdout.strip() == f"tetrig {version}", f"installed tetrig --version: {tool.stdout.strip()!r}")
        # The C API library exports its functions and nothing of the runtime inside it.
        nm = run(["nm", "-D", "--defined-only", os.path.join(lib, "libtetrig.so")])
        exported = [line.split()[-1] for line in nm.stdout.splitlines() if line.split() and line.split()[1] in "TDBRVW"]
        check("tetrig_rig_process_frame" in exported, "libtetrig.so does not export tetrig_rig_process_frame")
        linker_defined = {"_init", "_fini", "_edata", "_end", "__bss_start"}
        leaked = [s for s in exported if not s.startswith("tetrig_") and s not in linker_defined]
        check(not leaked, f"libtetrig.so exports symbols other than tetrig_*: {leaked[:8]}")

        # The public headers stand alone: each installed C++ header compiles by itself against the
        # installed tree (a header that reached for one of the runtime's internal headers, which are
        # not installed, fails here), and none of the internal headers is installed.
        env_pc = dict(os.environ, PKG_CONFIG_PATH=os.path.join(lib, "pkgconfig"))
        header_flags = run(["pkg-config", "--cflags", "tetrig-devices"], env=env_pc).stdout.split()
        include_root = os.path.join(prefix, "include")
        headers = sorted(os.path.relpath(os.path.join(d, f), include_root)
                         for d, _, files in os.walk(os.path.join(include_root, "tetrig")) for f in files if f.endswith(".hpp"))
        check(len(headers) > 10, f"only {len(headers)} C++ headers installed")
        for header in headers:
            compiled = subprocess.run(["c++", "-std=c++20", "-fsyntax-only", "-Wall", "-Wextra", "-Werror", "-x", "c++", "-"] + header_flags,
                                      input=f"#include <{header}>\n", capture_output=True, text=True)
            check(compiled.returncode == 0, f"the installed header {header} does not compile on its own: {compiled.stderr[-600:]}")
        internal = sorted(os.listdir(os.path.join(source_dir, "runtime", "internal", "tetrig")))
        installed_internal = [h for h in internal if os.path.exists(os.path.join(include_root, "tetrig", h))]
        check(len(internal) > 10 and not installed_internal, f"internal headers installed: {installed_internal}")
        print(f"{len(headers)} installed C++ headers compile on their own; {len(internal)} internal headers not installed")

        # 2. The outside project with the CMake package.
        built = {}
        cmake_build = os.path.join(tmp, "build-cmake")
        configure = run([cmake, "-S", consumer_src, "-B", cmake_build, "-G", "Ninja", "-DCMAKE_BUILD_TYPE=Release",
                         f"-DCMAKE_PREFIX_PATH={prefix}", f"-DTETRIG_EXPECTED_VERSION={version}"])
        if check(configure.returncode == 0, "configuring the consumer with find_package(tetrig CONFIG)"):
            if check(run([cmake, "--build", cmake_build]).returncode == 0, "building the consumer with the CMake package"):
                built["cmake C"] = os.path.join(cmake_build, "consumer_c")
                built["cmake C++"] = os.path.join(cmake_build, "consumer_cpp")
                devices = os.path.join(cmake_build, "consumer_devices")
                if check(os.path.exists(devices), "consumer_devices was not built (the package has no tetrig::devices)"):
                    check(run([devices]).returncode == 0, "consumer_devices")

        # 3. The outside project with pkg-config (the same sources, plain compiler command lines).
        env = dict(os.environ, PKG_CONFIG_PATH=os.path.join(lib, "pkgconfig"))
        modversion = run(["pkg-config", "--modversion", "tetrig"], env=env)
        check(modversion.stdout.strip() == version, f"pkg-config --modversion tetrig: {modversion.stdout.strip()!r}")
        c_flags = run(["pkg-config", "--cflags", "--libs", "tetrig"], env=env).stdout.split()
        cpp_flags = run(["pkg-config", "--cflags", "--libs", "tetrig-drivers"], env=env).stdout.split()
        check(all(prefix in flag for flag in c_flags if flag.startswith(("-I", "-L"))), f"pkg-config points outside the prefix: {c_flags}")
        pc_c = os.path.join(tmp, "consumer_c_pc")
        pc_cpp = os.path.join(tmp, "consumer_cpp_pc")
        if check(run(["cc", "-std=c99", "-pedantic", "-Werror", "-Wall", "-Wextra", "-O2", os.path.join(consumer_src, "consumer.c"), "-o", pc_c]
                     + c_flags + [f"-Wl,-rpath,{lib}"]).returncode == 0, "building consumer.c with pkg-config tetrig"):
            built["pkg-config C"] = pc_c
        if check(run(["c++", "-std=c++20", "-O3", "-DNDEBUG", os.path.join(consumer_src, "consumer.cpp"), "-o", pc_cpp] + cpp_flags).returncode == 0,
                 "building consumer.cpp with pkg-config tetrig-drivers"):
            built["pkg-config C++"] = pc_cpp
        if failures:
            print(f"{failures} checks FAILED")
            return 1

        # 4. Run them on the real rig and clip; compare with the in-tree C99 test's result.
        clip = data.require(source_dir, data.CLIP)
        if not check(os.path.exists(rig), f"the rig {rig} is missing (the capi_rig fixture builds it)"):
            return 1
        reference = os.path.join(tmp, "reference.f32")
        check(run([c99_test, source_dir, rig, frames, reference]).returncode == 0, "the in-tree test_capi_c99")
        with open(reference, "rb") as f:
            expected = f.read()
        check(len(expected) > 0, "no in-tree result")
        for name, exe in built.items():
            out = os.path.join(tmp, name.replace(" ", "_").replace("+", "p") + ".f32")
            if check(run([exe, rig, clip, frames, out]).returncode == 0, f"running the {name} consumer"):
                with open(out, "rb") as f:
                    check(f.read() == expected, f"the {name} consumer's positions differ from the in-tree result")
        print(f"consumers run: {', '.join(built)}")
    if failures:
        print(f"{failures} checks FAILED")
        return 1
    print("passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
