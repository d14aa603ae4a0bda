"""The Python package against the command line and its own promises: equal images for equal
arguments (bit for bit with `path`), one kernel build for a gate sweep on one Renderer, the
documented array layout, Python exceptions for bad input, the GIL released and Ctrl-C honoured
while rendering. GPU tests: they fail (never skip) without a Vulkan device."""

import json
import os
import signal
import struct
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

import gatetrace

ROOT = Path(__file__).resolve().parents[2]
BOX = ROOT / "assets/scenes/cornell_box.gltf"


def cli_binary() -> Path:
    """The command line `cargo test` built (GATETRACE_BIN, as tools/test.sh sets it)."""
    if "GATETRACE_BIN" in os.environ:
        path = Path(os.environ["GATETRACE_BIN"])
    else:
        built = [ROOT / "target" / p / "gatetrace" for p in ("release", "debug")]
        built = [p for p in built if p.exists()]
        assert built, "no gatetrace binary in target/: run cargo build or set GATETRACE_BIN"
        path = max(built, key=lambda p: p.stat().st_mtime)
    assert path.exists(), f"{path}: no such binary (set GATETRACE_BIN to the command line to compare with)"
    return path


def cli_render(tmp_path: Path, *args: str) -> tuple:
    out = tmp_path / "cli.npy"
    subprocess.run([str(cli_binary()), "render", *args, "--out", str(out)], check=True, capture_output=True)
    return np.load(out), json.loads(out.with_suffix(".json").read_text())


def test_one_call_render_equals_the_command_line_bit_for_bit(tmp_path):
    image = gatetrace.render(str(BOX), gate="box:3.14..3.19", spp=64, res=(64, 64), seed=1)
    assert image.shape == (64, 64, 3) and image.dtype == np.float32
    cli, _ = cli_render(tmp_path, str(BOX), "--gate", "box:3.14..3.19", "--spp", "64", "--res", "64x64", "--seed", "1")
    assert image.mean() > 0
    assert np.array_equal(image, cli), f"largest difference {np.abs(image - cli).max()}"


def test_a_fog_equals_the_command_lines_bit_for_bit(tmp_path):
    renderer = gatetrace.Renderer(gatetrace.Scene.load(BOX, fog=[0.5, 0.9, 0.7]), res=(32, 24), max_bounces=4)
    image, meta = renderer.render("none", spp=16, seed=3)
    cli, cli_meta = cli_render(tmp_path, str(BOX), "--fog", "0.5,0.9,0.7", "--spp", "16", "--res", "32x24",
                               "--max-bounces", "4", "--seed", "3")
    assert image.mean() > 0
    assert np.array_equal(image, cli), f"largest difference {np.abs(image - cli).max()}"
    clear, _ = gatetrace.Renderer(gatetrace.Scene.load(BOX), res=(32, 24), max_bounces=4).render("none", spp=16, seed=3)
    assert image.mean() < clear.mean()
    assert cli_meta["media"][0]["sigma_t_per_m"] == 0.5 and cli_meta["camera_medium"] == 0


def test_transient_cube_equals_the_command_line_and_has_the_documented_layout(tmp_path):
    renderer = gatetrace.Renderer(gatetrace.Scene.load(BOX), res=(32, 24), max_bounces=4)
    gate = gatetrace.transient(1.9, 0.1, 6)
    image, meta = renderer.render(gate, spp=16, seed=7)
    assert image.shape == (24, 32, 6, 3) and image.dtype == np.float32
    assert image.flags["C_CONTIGUOUS"]
    cli, cli_meta = cli_render(tmp_path, str(BOX), "--gate", str(gate), "--spp", "16", "--res", "32x24",
                               "--max-bounces", "4", "--seed", "7")
    assert np.array_equal(image, cli)
    for key in ("method", "gate", "gate_parameters", "spp", "seed", "max_bounces", "resolution"):
        assert meta[key] == cli_meta[key], key
    assert meta["spp"] == 16 and meta["seed"] == 7 and meta["method"] == "path"
    assert meta["resolution"] == [32, 24] and meta["max_bounces"] == 4
    assert meta["gate_parameters"] == {"kind": "transient", "start_m": 1.9, "bin_width_m": 0.1, "bins": 6,
                                       "end_m": pytest.approx(2.5)}


def test_queries_over_the_wide_bvh_equal_the_command_line_bit_for_bit(tmp_path):
    args = dict(gate="box:3.14..3.19", spp=16, res=(16, 16), max_bounces=3, seed=2, method="ellipsoidal")
    image, meta = gatetrace.render(str(BOX), query_tree="wide", metadata=True, **args)
    cli, cli_meta = cli_render(tmp_path, str(BOX), "--gate", "box:3.14..3.19", "--spp", "16", "--res", "16x16",
                               "--max-bounces", "3", "--seed", "2", "--method", "ellipsoidal", "--query-tree", "wide")
    assert image.mean() > 0 and meta["query_tree"] == cli_meta["query_tree"] == "wide"
    assert np.array_equal(image, cli), f"largest difference {np.abs(image - cli).max()}"
    # The default tree is the binary one.
    assert gatetrace.render(str(BOX), metadata=True, **args)[1]["query_tree"] == "binary"


def test_row_zero_is_the_top_of_the_image():
    # The Cornell box's light is in the ceiling: the brightest row lies in the upper half.
    image = gatetrace.render(BOX, spp=16, res=(32, 32), max_bounces=0)
    rows = image.sum(axis=(1, 2))
    assert rows.max() > 0 and int(np.argmax(rows)) < 16


def test_a_gate_sweep_on_one_renderer_builds_kernels_once_and_equals_fresh_renders():
    scene = gatetrace.Scene.load(BOX)
    renderer = gatetrace.Renderer(scene, res=(32, 32), max_bounces=4)
    starts = [3.0 + 0.05 * i for i in range(10)]
    images = []
    for i, start in enumerate(starts):
        images.append(renderer.render(gatetrace.box(start, start + 0.05), spp=8, seed=3)[0])
        if i == 0:
            built = gatetrace.kernels_built()
    assert gatetrace.kernels_built() == built, "moving the gate rebuilt kernels"
    assert sum(float(im.sum()) for im in images) > 0
    # The sweep's renders equal fresh renderers' (the integrator restarts from the seed).
    for i in (0, 6):
        fresh = gatetrace.Renderer(scene, res=(32, 32), max_bounces=4).render(
            gatetrace.box(starts[i], starts[i] + 0.05), spp=8, seed=3)[0]
        assert np.array_equal(images[i], fresh), f"gate {i}"
    # The device keeps the kernels it built: fresh renderers with the same settings build none.
    assert gatetrace.kernels_built() == built, "a fresh renderer rebuilt the kernels"
    # A gate of another kind needs other kernels, built on the same renderer, once: renders of
    # the steady state after it reuse them.
    steady, _ = renderer.render("none", spp=2)
    assert steady.shape == (32, 32, 3) and steady.mean() > 0
    built = gatetrace.kernels_built()
    again, _ = renderer.render("none", spp=2, seed=5)
    assert gatetrace.kernels_built() == built, "a second steady render rebuilt kernels"
    assert again.mean() > 0 and not np.array_equal(again, steady)


def test_bidirectional_methods_agree_with_path_on_the_image_mean():
    gate = gatetrace.box(3.14, 3.24)
    means = {}
    for method in ("path", "direct", "ellipsoidal", "combined"):
        image, meta = gatetrace.render(BOX, gate=gate, spp=64, res=(16, 16), max_bounces=3, method=method, seed=5,
                                       metadata=True)
        assert meta["method"] == method
        means[method] = float(image.mean())
    for method in ("direct", "ellipsoidal", "combined"):
        # 64 spp of 256 pixels: the image means agree to a few per cent.
        assert abs(means[method] / means["path"] - 1) < 0.1, means


@pytest.mark.parametrize(
    "call, error, words",
    [
        (lambda: gatetrace.Scene.load(ROOT / "no/such/scene.gltf"), FileNotFoundError, "no such file"),
        (lambda: gatetrace.Scene.load(ROOT / "README.md"), ValueError, "README.md"),
        (lambda: gatetrace.Scene.load(BOX, aperture_radius=0.01), ValueError, "focus_distance="),
        (lambda: gatetrace.Scene.load(BOX, fog=[0.0]), ValueError, "extinction"),
        (lambda: gatetrace.Scene.load(BOX, aperture_radius=0.01, focus_distance=-1.0), ValueError, "-1 m"),
        (lambda: gatetrace.Renderer(BOX, method="bidirectional"), ValueError, "method"),
        (lambda: gatetrace.Renderer(BOX, res=(0, 64)), ValueError, "res"),
        (lambda: gatetrace.Renderer(BOX, res=64), ValueError, "res"),
        (lambda: gatetrace.Renderer(BOX, max_bounces=-1), ValueError, "max_bounces"),
        (lambda: gatetrace.Renderer(BOX, query_weights="angles"), ValueError, "query_weights"),
        (lambda: gatetrace.Renderer(BOX, query_tree="octree"), ValueError, "query_tree"),
        (lambda: gatetrace.render(BOX, gate="box:3.2..3.1", spp=1, res=(8, 8)), ValueError, "gate"),
        (lambda: gatetrace.render(BOX, gate="boxcar:1..2", spp=1, res=(8, 8)), ValueError, "boxcar"),
        (lambda: gatetrace.render(BOX, gate=3.14, spp=1, res=(8, 8)), TypeError, "gate"),
        (lambda: gatetrace.render(BOX, spp=0, res=(8, 8)), ValueError, "spp"),
        (lambda: gatetrace.render(BOX, spp=1, seconds=1.0, res=(8, 8)), ValueError, "not both"),
        (lambda: gatetrace.render(BOX, seconds=-1.0, res=(8, 8)), ValueError, "seconds"),
        (lambda: gatetrace.render(BOX, spp=1, seed=-1, res=(8, 8)), ValueError, "seed"),
        (lambda: gatetrace.render(BOX, spp=1, res=(8, 8), method="ellipsoidal"), ValueError, "gate"),
        (lambda: gatetrace.render(BOX, spp=1, res=(8, 8), method="combined"), ValueError, "needs a gate"),
        (lambda: gatetrace.render(BOX, gate="table:/no/such.csv", spp=1, res=(8, 8)), ValueError, "such.csv"),
    ],
)
def test_bad_arguments_raise_python_exceptions(call, error, words):
    with pytest.raises(error) as caught:
        call()
    assert words in str(caught.value), str(caught.value)


def test_transmissive_materials_are_refused_unless_allowed(tmp_path):
    doc = json.loads(BOX.read_text())
    doc["materials"][1].setdefault("extensions", {})["KHR_materials_transmission"] = {"transmissionFactor": 1.0}
    doc["extensionsUsed"].append("KHR_materials_transmission")
    glass = tmp_path / "glass.gltf"
    glass.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as caught:
        gatetrace.Scene.load(glass)
    for words in ("glass.gltf", "material `red`", "KHR_materials_transmission", "allow_unsupported_materials"):
        assert words in str(caught.value), str(caught.value)
    with pytest.warns(RuntimeWarning, match="opaque surface"):
        assert gatetrace.Scene.load(glass, allow_unsupported_materials=True).triangles > 0


def test_what_loading_ignores_comes_as_a_python_warning(tmp_path):
    doc = json.loads(BOX.read_text())
    doc["materials"][0].setdefault("extensions", {})["KHR_materials_clearcoat"] = {"clearcoatFactor": 1.0}
    doc["extensionsUsed"].append("KHR_materials_clearcoat")
    coated = tmp_path / "coated.gltf"
    coated.write_text(json.dumps(doc))
    with pytest.warns(RuntimeWarning, match="KHR_materials_clearcoat") as caught:
        scene = gatetrace.Scene.load(coated)
    assert scene.triangles > 0
    assert any("coated.gltf" in str(w.message) and "material `white`" in str(w.message) for w in caught)


def test_scenes_in_other_formats_say_what_they_are(tmp_path):
    obj = tmp_path / "plane.obj"
    obj.write_text("o Plane\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(ValueError) as caught:
        gatetrace.Scene.load(obj)
    for words in ("plane.obj", "Wavefront OBJ", ".gltf or .glb", "File > Export > glTF 2.0"):
        assert words in str(caught.value), str(caught.value)


def test_units_and_gate_constructors_speak_the_command_line():
    assert gatetrace.ps(1000) == pytest.approx(0.299792458)
    assert gatetrace.ns(1) == pytest.approx(0.299792458)
    assert gatetrace.mm(5) == pytest.approx(0.005)
    assert str(gatetrace.box(3.14, 3.19)) == "box:3.14..3.19"
    assert str(gatetrace.transient(1.9, 0.01, 100)) == "transient:1.9,0.01,100"
    assert str(gatetrace.cw(20e6, 90, "ham3")) == "cw:20000000.0,90.0,ham3"
    for gate in (gatetrace.box(3.14, 3.19), gatetrace.gaussian(3.0, 0.01), gatetrace.cw(20e6, 90),
                 gatetrace.transient(1.9, gatetrace.ps(10), 8), gatetrace.none()):
        assert gate.describe()


def test_scene_shows_its_camera_lights_and_nodes():
    scene = gatetrace.Scene.load(BOX)
    assert scene.triangles > 0
    assert scene.camera["position"] == pytest.approx([0.0, 0.0, 2.0])
    assert scene.camera["aperture_radius"] is None
    assert [l["type"] for l in scene.lights] == ["area"]
    assert "camera" in scene.nodes
    lens = gatetrace.Scene.load(BOX, aperture_radius=0.01, focus_distance=2.0)
    assert lens.camera["aperture_radius"] == pytest.approx(0.01)


def test_the_gil_is_released_while_rendering():
    renderer = gatetrace.Renderer(BOX, res=(64, 64))
    renderer.render("none", spp=1)  # builds the kernels
    ticks = 0
    done = threading.Event()

    def count():
        nonlocal ticks
        while not done.is_set():
            ticks += 1
            time.sleep(0.001)

    thread = threading.Thread(target=count)
    thread.start()
    start = time.perf_counter()
    renderer.render("none", seconds=1.0)
    elapsed = time.perf_counter() - start
    done.set()
    thread.join()
    # A thread that needs the GIL every millisecond ran throughout the render.
    assert ticks > 100 * elapsed, f"{ticks} ticks in {elapsed:.2f} s"


def test_ctrl_c_stops_a_long_render_and_leaves_the_renderer_usable():
    import _thread

    renderer = gatetrace.Renderer(BOX, res=(64, 64))
    renderer.render("none", spp=1)
    # A shell starts background jobs (`tools/test.sh &`, batch runners) with SIGINT ignored, and
    # then Python raises no KeyboardInterrupt: install the handler this test relies on.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        timer = threading.Timer(1.0, _thread.interrupt_main)
        timer.start()
        start = time.perf_counter()
        with pytest.raises(KeyboardInterrupt):
            renderer.render("none", seconds=60.0)
        assert time.perf_counter() - start < 20.0
        timer.join()
    finally:
        signal.signal(signal.SIGINT, previous)
    image, meta = renderer.render("none", spp=2, seed=1)
    assert meta["spp"] == 2 and image.mean() > 0


def test_ctrl_c_stops_a_render_in_a_background_job_with_stdin_closed():
    # A shell starts background jobs (`nohup tools/test.sh &`, batch runners) with SIGINT
    # ignored; the Ctrl-C test must pass there too.
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", __file__, "-k",
         "test_ctrl_c_stops_a_long_render_and_leaves_the_renderer_usable"],
        stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=300,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert done.returncode == 0 and "1 passed" in done.stdout, done.stdout[-3000:]


def test_nlos_tools_read_a_capture_whose_gate_was_typed_in_ns_and_ps(tmp_path):
    # The sidecar holds the gate in metres beside the spec as typed, so the tools downstream
    # accept every unit the command line does.
    capture = tmp_path / "capture.npy"
    subprocess.run([str(cli_binary()), "render", str(ROOT / "assets/scenes/nlos_letter.gltf"), "--nlos", "confocal",
                    "--res", "8x8", "--gate", "transient:3.002ns,13.34ps,400", "--max-bounces", "3", "--spp", "16",
                    "--out", str(capture)], check=True, capture_output=True)
    meta = json.loads(capture.with_suffix(".json").read_text())
    assert meta["gate"] == "transient:3.002ns,13.34ps,400"
    gate = meta["gate_parameters"]
    assert gate["kind"] == "transient" and gate["bins"] == 400
    assert gate["start_m"] == pytest.approx(3.002 * 0.299792458, rel=1e-12)
    assert gate["bin_width_m"] == pytest.approx(13.34e-3 * 0.299792458, rel=1e-12)
    assert meta["spp"] == 16 and isinstance(meta["elapsed_seconds"], float)

    picture = tmp_path / "picture.npy"
    done = subprocess.run([sys.executable, str(ROOT / "tools/nlos/nlos_backproject.py"), str(capture), "--voxels", "16",
                           "-o", str(picture)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    back = np.load(picture)
    assert back.shape == (16, 16) and np.isfinite(back).all() and back.max() == pytest.approx(1.0)
    # The picture as a PNG, whatever imaging libraries are installed: 4 pixels a voxel, the same
    # grey levels.
    png = tmp_path / "picture.png"
    done = subprocess.run([sys.executable, str(ROOT / "tools/nlos/nlos_backproject.py"), str(capture), "--voxels", "16",
                           "-o", str(png)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    width, height, depth, colour = struct.unpack(">IIBB", data[16:26])
    assert (width, height, depth, colour) == (64, 64, 8, 0)
    idat = data.index(b"IDAT")
    size = struct.unpack(">I", data[idat - 4:idat])[0]
    rows = np.frombuffer(zlib.decompress(data[idat + 4:idat + 4 + size]), dtype=np.uint8).reshape(64, 65)
    assert (rows[:, 0] == 0).all()
    assert np.array_equal(rows[::4, 1::4], np.round(back * 255).astype(np.uint8))

    import h5py  # a test requirement (pyproject.toml), as tools/nlos/nlos_to_hdf5.py needs it
    hdf5 = tmp_path / "capture.hdf5"
    done = subprocess.run([sys.executable, str(ROOT / "tools/nlos/nlos_to_hdf5.py"), str(capture), "-o", str(hdf5)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    with h5py.File(hdf5) as f:
        assert f["H"].shape == (400, 8, 8)
        assert float(f["delta_t"][()]) == pytest.approx(gate["bin_width_m"], rel=1e-6)
        assert float(f["t_start"][()]) == pytest.approx(gate["start_m"], rel=1e-6)


LETTER = ROOT / "assets/scenes/nlos_letter.gltf"


def test_confocal_capture_equals_the_command_line_bit_for_bit(tmp_path):
    gate = gatetrace.transient(0.9, 0.1, 8)
    data, meta = gatetrace.capture(LETTER, "confocal", gate, res=(8, 8), max_bounces=3, spp=64, seed=3)
    assert data.shape == (8, 8, 8, 3) and data.dtype == np.float32
    cli, cli_meta = cli_render(tmp_path, str(LETTER), "--nlos", "confocal", "--gate", str(gate), "--res", "8x8",
                               "--max-bounces", "3", "--spp", "64", "--seed", "3")
    assert data.sum() > 0
    assert np.array_equal(data, cli), f"largest difference {np.abs(data - cli).max()}"
    for key in ("method", "gate_parameters", "spp", "seed", "max_bounces", "resolution", "connections_per_query",
                "query_weights", "target_pilot_spp", "units", "nlos_scan", "relay_wall", "sensor_origin",
                "laser_origin", "laser_power_w", "sensor_grid_xyz", "laser_grid_xyz"):
        assert meta[key] == cli_meta[key], key
    assert meta["method"] == "ellipsoidal" and meta["nlos_scan"] == "confocal"


PANELS = ROOT / "assets/scenes/nlos_panels.xml"


def test_a_mitsuba_capture_takes_the_files_setup_and_equals_the_command_line(tmp_path):
    # Nothing but the file: its single scan, 8x8 grid, 100 bins, three bounces, projector laser.
    data, meta = gatetrace.capture(PANELS, spp=16, method="path", seed=5)
    assert data.shape == (8, 8, 100, 3) and data.sum() > 0
    assert meta["nlos_scan"] == "single" and meta["max_bounces"] == 3
    assert meta["laser_power_w"] is None and meta["laser_projector_irradiance_w_m2"] == [1.0, 1.0, 1.0]
    cli, cli_meta = cli_render(tmp_path, str(PANELS), "--spp", "16", "--method", "path", "--seed", "5")
    assert np.array_equal(data, cli), f"largest difference {np.abs(data - cli).max()}"
    for key in ("gate_parameters", "resolution", "sensor_origin", "laser_origin", "laser_grid_xyz", "relay_wall"):
        assert meta[key] == cli_meta[key], key
    # Its parameter, and arguments over the file's settings.
    data, meta = gatetrace.capture(PANELS, parameters={"confocal": "true"}, res=(4, 4), spp=4, method="path", laser_power=2.0)
    assert data.shape == (4, 4, 100, 3)
    assert meta["nlos_scan"] == "confocal" and meta["laser_power_w"] == 2.0
    with pytest.raises(ValueError, match="give scan"):
        gatetrace.capture(LETTER, gate="transient:0.9,0.02,8", res=(4, 4), max_bounces=3, spp=1)


@pytest.mark.parametrize(
    "options, error, words",
    [
        (dict(relay_wall="no_such_wall"), ValueError, "no node named `no_such_wall`"),
        (dict(scan="sideways"), ValueError, "scan `sideways`"),
        (dict(max_bounces=1), ValueError, "max-bounces"),
        (dict(laser_grid=(2, 2)), ValueError, "laser-grid needs --nlos exhaustive"),
        (dict(method="auto"), ValueError, "method auto does not apply to NLOS captures"),
        (dict(laser_power=-1.0), ValueError, "laser power"),
        (dict(sensor_origin=(0.0, 1.0)), ValueError, "sensor_origin"),
        (dict(band_index="maybe"), ValueError, "band_index"),
    ],
)
def test_bad_capture_options_raise_python_exceptions_naming_the_problem(options, error, words):
    arguments = dict(scan="confocal", gate="transient:0.9,0.02,8", res=(4, 4), max_bounces=3, spp=1)
    arguments.update(options)
    with pytest.raises(error) as caught:
        gatetrace.capture(LETTER, **arguments)
    assert words in str(caught.value), str(caught.value)


def test_exhaustive_capture_has_the_command_lines_layout_and_values(tmp_path):
    data, meta = gatetrace.capture(LETTER, "exhaustive", "transient:0.9,0.1,8", res=(3, 2), laser_grid=(2, 2),
                                   max_bounces=3, spp=64, seed=5)
    assert data.shape == (2, 2, 2, 3, 8, 3) and data.dtype == np.float32
    cli, _ = cli_render(tmp_path, str(LETTER), "--nlos", "exhaustive", "--gate", "transient:0.9,0.1,8", "--res", "3x2",
                        "--laser-grid", "2x2", "--max-bounces", "3", "--spp", "64", "--seed", "5")
    assert np.array_equal(data, cli)
    assert meta["nlos_scan"] == "exhaustive" and np.array(meta["laser_grid_xyz"]).shape == (2, 2, 3)


def test_a_mitsuba_scene_renders_with_its_own_settings_as_the_command_line_does(tmp_path):
    xml = ROOT / "assets/scenes/mitsuba_box/scene.xml"
    scene = gatetrace.Scene.load(xml)
    assert scene.settings == {"res": (32, 32), "spp": 64, "max_bounces": 5, "gate": "transient:1.94,0.1,20",
                              "seed": None}
    assert gatetrace.Scene.load(BOX).settings == {"res": None, "spp": None, "max_bounces": None, "gate": None,
                                                  "seed": None}
    image, meta = gatetrace.render(scene, metadata=True)
    assert image.shape == (32, 32, 20, 3) and meta["spp"] == 64 and meta["max_bounces"] == 5
    cli, cli_meta = cli_render(tmp_path, str(xml))
    assert cli_meta["gate"] == meta["gate"] == "transient:1.94,0.1,20"
    assert image.mean() > 0 and np.array_equal(image, cli), f"largest difference {np.abs(image - cli).max()}"
    # Arguments override the file's settings; parameters replace its defaults.
    small = gatetrace.render(scene, gate="none", spp=2, res=(8, 4), max_bounces=1)
    assert small.shape == (4, 8, 3)
    assert gatetrace.Scene.load(xml, parameters={"res": "8", "bins": "3"}).settings["res"] == (8, 8)
