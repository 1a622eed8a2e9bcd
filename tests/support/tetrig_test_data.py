"""Where the real test data lives, for the Python tests (the same rules as test_data.hpp).

The data root is $TETRIG_DATA_DIR when set, else <source>/../shared/data. A test that needs a file
calls require(): when the file is absent the test exits with SKIP (77, the ctest SKIP_RETURN_CODE of
these tests) and says which path it looked for; under CI (CI=true or CI=1) an absent file is a
failure instead, since CI has the data.
"""
import os
import sys

SKIP = 77


def data_root(source_dir):
    env = os.environ.get("TETRIG_DATA_DIR", "")
    return env if env else os.path.join(source_dir, "..", "shared", "data")


def running_in_ci():
    return os.environ.get("CI", "") in ("true", "1")


def require(source_dir, relative):
    """The absolute path of data file `relative`; skips (or fails under CI) when it is absent."""
    path = os.path.abspath(os.path.join(data_root(source_dir), relative))
    if not os.path.exists(path):
        if running_in_ci():
            print(f"FAILED: test data missing in CI: {path} (set TETRIG_DATA_DIR)")
            sys.exit(1)
        print(f"SKIPPED: test data not found: {path} (place ../shared/data beside the checkout or set TETRIG_DATA_DIR)")
        sys.exit(SKIP)
    return path


# The real rig of the C API and install tests: the SMPL male rigged to the HDM05 markers.
MESH = "meshes/odedstein-meshes/human_man.obj"
CLIP = "mocap/hdm05/HDM_mm_01-02_03_120.c3d"
