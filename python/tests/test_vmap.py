"""The Python binding against the library's other paths: the CLI's files and answers, the
visible sets, round trips through arrays and files, and bad input. Run by ctest (Python.Pytest)
with PYTHONPATH at the built module and VMAP_BIN at the vmap binary."""
import os
import subprocess

import numpy as np
import pytest

import vmap

SCENE = os.path.join(vmap.data_dir(), "scenes", "cornell-empty.json")
OPTS = dict(max_height=5, leaf_points=4, backend="cpu")


@pytest.fixture(scope="module")
def small():
    return vmap.build_file(SCENE, points=2000, seed=3, **OPTS)


def vmap_bin():
    path = os.environ.get("VMAP_BIN")
    if not path:
        pytest.skip("VMAP_BIN is not set (ctest sets it)")
    return path


def test_build_file_writes_the_same_bytes_as_the_cli(small, tmp_path):
    py_file, cli_file = tmp_path / "py.vmap", tmp_path / "cli.vmap"
    small.save(str(py_file))
    subprocess.run([vmap_bin(), "-q", "build", SCENE, "--points", "2000", "--seed", "3",
                    "--max-height", "5", "--leaf-points", "4", "--backend", "cpu", "-o",
                    str(cli_file)], check=True)
    assert py_file.read_bytes() == cli_file.read_bytes()


def test_query_agrees_with_the_cli_batch(small, tmp_path):
    rng = np.random.default_rng(1)
    pairs = rng.integers(0, small.num_points, size=(500, 2))
    small.save(str(tmp_path / "m.vmap"))
    np.savetxt(tmp_path / "pairs.txt", pairs, fmt="%d")
    out = subprocess.run([vmap_bin(), "query", str(tmp_path / "m.vmap"), "--pairs",
                          str(tmp_path / "pairs.txt")], check=True, capture_output=True,
                         text=True).stdout.split("\n")
    words = {"hidden": 0, "visible": 1, "same-leaf": 2}
    cli = np.array([words[line.split()[2]] for line in out if line])
    assert np.array_equal(small.query_codes(pairs), cli)
    assert np.array_equal(small.query(pairs), cli == 1)


def test_query_matches_the_visible_sets(small):
    rng = np.random.default_rng(2)
    pairs = rng.integers(0, small.num_points, size=(300, 2))
    codes = small.query_codes(pairs)
    offsets, targets = small.visible_from(pairs[:, 0])
    assert offsets.dtype == np.uint64 and len(offsets) == len(pairs) + 1
    for k, (i, j) in enumerate(pairs):
        seen = targets[offsets[k]:offsets[k + 1]]
        assert np.array_equal(seen, small.visible_set(i))
        if codes[k] != 2:
            assert (codes[k] == 1) == (j in seen)
    assert codes.dtype == np.uint8 and set(np.unique(codes)) <= {0, 1, 2}


def test_build_from_arrays_round_trips(small):
    # Arrays are a point cloud (the 2.25 floor) unless told the scene's floor (2.0, blue noise).
    assert small.delta_floor == 2.0
    again = vmap.build(small.points, small.normals, small.radii, small.colors, small.emission,
                       delta_floor=small.delta_floor, **OPTS)
    assert again.num_links == small.num_links
    assert again.num_leaves == small.num_leaves
    pairs = np.random.default_rng(4).integers(0, small.num_points, size=(2000, 2))
    assert np.array_equal(again.query_codes(pairs), small.query_codes(pairs))
    assert np.allclose(again.points, small.points)


def test_save_and_load(small, tmp_path):
    small.save(str(tmp_path / "a.vmap"))
    back = vmap.load(str(tmp_path / "a.vmap"))
    assert (back.num_points, back.num_links, back.height) == (
        small.num_points, small.num_links, small.height)


def test_uniform_sampling_matches_the_cli(small, tmp_path):
    py_file, cli_file = tmp_path / "py.vmap", tmp_path / "cli.vmap"
    uni = vmap.build_file(SCENE, points=2000, seed=3, sampling="uniform", **OPTS)
    assert uni.delta_floor == 2.25 and small.delta_floor == 2.0  # independent, blue noise
    uni.save(str(py_file))
    subprocess.run([vmap_bin(), "-q", "build", SCENE, "--points", "2000", "--seed", "3",
                    "--max-height", "5", "--leaf-points", "4", "--backend", "cpu",
                    "--sampling", "uniform", "-o", str(cli_file)], check=True)
    assert py_file.read_bytes() == cli_file.read_bytes()
    with pytest.raises(vmap.Error, match="sampling"):
        vmap.build_file(SCENE, points=500, sampling="poisson", **OPTS)


def test_delta_floor_matches_the_cli(small, tmp_path):
    py_file, cli_file = tmp_path / "py.vmap", tmp_path / "cli.vmap"
    vmap.build_file(SCENE, points=2000, seed=3, delta_floor=1.5, **OPTS).save(str(py_file))
    subprocess.run([vmap_bin(), "-q", "build", SCENE, "--points", "2000", "--seed", "3",
                    "--max-height", "5", "--leaf-points", "4", "--backend", "cpu",
                    "--delta-floor", "1.5", "-o", str(cli_file)], check=True)
    assert py_file.read_bytes() == cli_file.read_bytes()
    small_file = tmp_path / "small.vmap"
    small.save(str(small_file))
    assert py_file.read_bytes() != small_file.read_bytes()


def test_end_window_matches_the_cli(small, tmp_path):
    py_file, cli_file = tmp_path / "py.vmap", tmp_path / "cli.vmap"
    m = vmap.build_file(SCENE, points=2000, seed=3, end_window=3, **OPTS)
    assert m.end_window == 3.0 and small.end_window == 0.0
    m.save(str(py_file))
    subprocess.run([vmap_bin(), "-q", "build", SCENE, "--points", "2000", "--seed", "3",
                    "--max-height", "5", "--leaf-points", "4", "--backend", "cpu",
                    "--end-window", "3", "-o", str(cli_file)], check=True)
    assert py_file.read_bytes() == cli_file.read_bytes()
    assert vmap.load(str(py_file)).end_window == 3.0


def noisy_sphere(sigma, n=3000, seed=4):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p = 0.1 * p / np.linalg.norm(p, axis=1, keepdims=True)
    return (p + rng.normal(scale=sigma, size=p.shape)).astype(np.float32)


def test_surface_noise_and_roughness(tmp_path):
    exact, rough = noisy_sphere(0.0), noisy_sphere(0.001)
    assert vmap.surface_noise(exact)["roughness"] == 0.0
    n = vmap.surface_noise(rough)
    assert abs(n["sigma"] - 0.001) < 0.0002 and n["spacing"] > 0
    assert abs(n["roughness"] - 4.2426 * n["sigma"]) < 1e-6
    # build() takes the points' measured roughness unless given one; it is kept in the file
    m = vmap.build(rough, max_height=5, backend="cpu")
    assert m.roughness == pytest.approx(n["roughness"], rel=1e-6)
    m.save(str(tmp_path / "r.vmap"))
    assert vmap.load(str(tmp_path / "r.vmap")).roughness == m.roughness
    assert vmap.build(rough, max_height=5, backend="cpu", roughness=0.0).roughness == 0.0
    assert vmap.build(exact, max_height=5, backend="cpu").roughness == 0.0


def test_core_is_an_option_and_kept(tmp_path):
    exact = noisy_sphere(0.0)
    m = vmap.build(exact, max_height=5, backend="cpu")
    assert m.core == pytest.approx(0.5)  # the default
    m0 = vmap.build(exact, max_height=5, backend="cpu", core=0.0)
    assert m0.core == 0.0
    m0.save(str(tmp_path / "c.vmap"))
    assert vmap.load(str(tmp_path / "c.vmap")).core == 0.0
    with pytest.raises(vmap.Error, match="core"):
        vmap.build(exact, max_height=5, backend="cpu", core=2.0)


def test_one_thread_gives_the_same_map(small):
    one = vmap.build_file(SCENE, points=2000, seed=3, threads=1, **OPTS)
    pairs = np.random.default_rng(5).integers(0, small.num_points, size=(2000, 2))
    assert one.num_links == small.num_links
    assert np.array_equal(one.query_codes(pairs), small.query_codes(pairs))


def test_normals_are_estimated_when_missing():
    rng = np.random.default_rng(6)
    # A closed box of 6 faces, 300 points each, seen from inside and out.
    faces = []
    for axis in range(3):
        for side in (0.0, 1.0):
            p = rng.random((300, 3))
            p[:, axis] = side
            faces.append(p)
    pts = np.concatenate(faces).astype(np.float32)
    vm = vmap.build(pts, max_height=4, backend="cpu")
    assert vm.num_points == len(pts) and vm.normals.shape == pts.shape
    assert np.allclose(np.linalg.norm(vm.normals, axis=1), 1, atol=1e-4)


def test_rays_hit_points_of_the_visible_set(small):
    origins = np.arange(0, small.num_points, 97)
    dirs = np.random.default_rng(7).normal(size=(len(origins), 3))
    hits, dist = small.shoot_rays(origins, dirs)
    assert hits.dtype == np.int64 and dist.dtype == np.float32
    for o, h, d in zip(origins, hits, dist):
        if h >= 0:
            assert h in small.visible_set(o) and np.isfinite(d) and d > 0
        else:
            assert np.isinf(d)


def test_render_and_gi_give_arrays(small):
    img = small.render(eye_id=10, width=64, height=48)
    assert img.shape == (48, 64, 3) and img.dtype == np.uint8 and img.std() > 0
    shaded = small.render(width=32, height=32)
    assert shaded.shape == (32, 32, 3)
    radiosity = small.gi(bounces=2)
    assert radiosity.shape == (small.num_points, 3) and radiosity.dtype == np.float32
    assert np.isfinite(radiosity).all() and radiosity.max() > 0


def test_progress_reports_and_cancels():
    seen = []

    def record(p):
        seen.append((p["done"], p["total"]))
        return True

    vmap.build_file(SCENE, points=1500, progress=record, **OPTS)
    assert seen[0][0] == 0 and seen[-1][0] == seen[-1][1] > 0
    assert all(a[0] <= b[0] for a, b in zip(seen, seen[1:]))
    with pytest.raises(vmap.Cancelled, match="cancelled"):
        vmap.build_file(SCENE, points=1500, progress=lambda p: False, **OPTS)


def test_bad_input_raises_the_library_message(small, tmp_path):
    with pytest.raises(vmap.Error, match="out of range"):
        small.query(np.array([[0, small.num_points]]))
    with pytest.raises(vmap.Error, match="M x 2"):
        small.query(np.array([1, 2, 3]))
    with pytest.raises(vmap.Error, match="N x 3"):
        vmap.build(np.zeros((10, 2), np.float32))
    with pytest.raises(vmap.Error, match="radii"):
        vmap.build(small.points, small.normals, radii=np.ones(3, np.float32))
    with pytest.raises(vmap.Error, match="nope.vmap"):
        vmap.load(str(tmp_path / "nope.vmap"))
    with pytest.raises(vmap.Error, match="K"):
        vmap.build_file(SCENE, points=500, K=0, backend="cpu")
    with pytest.raises(TypeError, match="max_hieght"):
        vmap.build_file(SCENE, points=500, max_hieght=3)
    assert issubclass(vmap.Error, RuntimeError) and issubclass(vmap.Cancelled, vmap.Error)


@pytest.mark.skipif(vmap.built_with_cuda, reason="a CUDA build may have a device")
def test_cuda_without_a_device_is_an_error():
    with pytest.raises(vmap.Error, match="backend cuda"):
        vmap.build_file(SCENE, points=500, max_height=4, backend="cuda")


def test_a_cloud_far_from_its_files_zero_keeps_its_coordinates(small, tmp_path):
    # The small room 4 million units out, as a georeferenced scan's file holds it (doubles).
    far = np.array([512345.0, 4123456.0, 210.0])
    pts = small.points.astype(np.float64) + far
    path = tmp_path / "far.ply"
    with open(path, "w") as f:
        f.write("ply\nformat ascii 1.0\nelement vertex %d\n" % len(pts))
        f.write("property double x\nproperty double y\nproperty double z\n")
        f.write("property float nx\nproperty float ny\nproperty float nz\nend_header\n")
        for p, n in zip(pts, small.normals):
            f.write("%.9f %.9f %.9f %g %g %g\n" % (*p, *n))
    vm = vmap.build_file(str(path), **OPTS)
    assert vm.origin == (512345.0, 4123456.0, 210.0)
    np.testing.assert_allclose(vm.points + np.array(vm.origin), pts, rtol=0, atol=1e-6)
    assert small.origin == (0.0, 0.0, 0.0)


def test_estimate_normals_signs_toward_a_viewpoint_sensors_and_a_scanner():
    rng = np.random.default_rng(5)
    # A room seen from inside, as a scanner on a tripod records it: beams on an equal-angle grid
    # from (0.5, 0.6, 0.4) to the walls of the unit cube (its front z = 0 open).
    at = np.array([0.5, 0.6, 0.4], np.float32)
    el, az = np.meshgrid(np.radians(np.arange(-88.5, 90, 1.5)), np.radians(np.arange(0, 360, 1.5)))
    d = np.stack([np.cos(el) * np.cos(az), np.sin(el), np.cos(el) * np.sin(az)], -1).reshape(-1, 3)
    t = np.full(len(d), np.inf)
    for axis, plane in [(0, 0), (0, 1), (1, 0), (1, 1), (2, 1)]:
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = (plane - at[axis]) / d[:, axis]
            hit = at + d * ta[:, None]
        inside = np.all((hit > -1e-4) & (hit < 1 + 1e-4), axis=1)
        t = np.where((ta > 0) & inside & (ta < t), ta, t)
    pts = (at + d[np.isfinite(t)] * t[np.isfinite(t), None]).astype(np.float32)
    r = vmap.estimate_normals(pts)
    assert r["normals"].shape == pts.shape
    assert np.allclose(np.linalg.norm(r["normals"], axis=1), 1, atol=1e-4)
    assert r["scanner"] is not None and "a scan from inside a room" in r["method"]
    assert all(0 < c < 1 for c in r["scanner"])
    # The walls face the room.
    assert np.mean(np.sum(r["normals"] * (np.float32(0.5) - pts), axis=1) > 0) > 0.99
    vp = vmap.estimate_normals(pts, viewpoint=(0.5, 0.5, 2.0))
    assert np.all(np.sum(vp["normals"] * (np.array([0.5, 0.5, 2.0]) - pts), axis=1) >= 0)
    assert vp["scanner"] is None
    sensors = rng.uniform(-1, 2, pts.shape).astype(np.float32)
    sn = vmap.estimate_normals(pts, sensors=sensors)
    assert np.all(np.sum(sn["normals"] * (sensors - pts), axis=1) >= 0)
    with pytest.raises(vmap.Error, match="sensors"):
        vmap.estimate_normals(pts, sensors=sensors[:-1])
    with pytest.raises(vmap.Error, match="viewpoint"):
        vmap.estimate_normals(pts, viewpoint=(1.0, 2.0))
    with pytest.raises(vmap.Error, match="points"):
        vmap.estimate_normals(np.zeros((0, 3), np.float32))


def test_estimate_normals_finds_a_lone_scans_scanner_by_its_spacing():
    # A lone bowl (the far half of a sphere) scanned from one side on an equal-angle grid
    # turning about y: no room, but the points' spacing tells where the scanner stood.
    at = np.array([0.5, 0.6, 0.3], np.float32)
    c, radius = np.array([0.5, 0.35, 0.7], np.float32), 0.15
    el, az = np.meshgrid(np.radians(np.arange(-89.5, 90, 0.5)), np.radians(np.arange(0, 360, 0.5)))
    d = np.stack([np.cos(el) * np.cos(az), np.sin(el), np.cos(el) * np.sin(az)], -1).reshape(-1, 3)
    o = at - c
    b = d @ o
    disc = b * b - (o @ o - radius * radius)
    t = np.full(len(d), np.nan)
    for sg in (1, -1):  # the nearer hit on the far half wins
        ts = -b + sg * np.sqrt(np.maximum(disc, 0))
        z = at[2] + d[:, 2] * ts
        t = np.where((disc >= 0) & (ts > 0) & (z >= c[2]), ts, t)
    pts = (at + d * t[:, None])[np.isfinite(t)].astype(np.float32)
    assert len(pts) > 1000
    r = vmap.estimate_normals(pts)
    assert len(r["scanners"]) == 1, r["method"]
    assert np.linalg.norm(np.array(r["scanners"][0]) - at) < 0.01
    assert "by the points' spacing" in r["method"]
    # The bowl's inside, which the scanner saw, faces it.
    assert np.mean(np.sum(r["normals"] * (c - pts), axis=1) > 0) > 0.95


def test_estimate_normals_keeps_a_boxs_faces_right_up_to_its_edges():
    # A box's surface, sampled uniformly: right at an edge every fit leans toward the other
    # face, and the crease pass gives such a point the plane of its own face.
    rng = np.random.default_rng(8)
    n = 20000
    pts = rng.uniform(0, 1, (n, 3)).astype(np.float32)
    axis = rng.integers(0, 3, n)
    side = rng.integers(0, 2, n).astype(np.float32)
    pts[np.arange(n), axis] = side
    truth = np.zeros((n, 3), np.float32)
    truth[np.arange(n), axis] = 1
    r = vmap.estimate_normals(pts)
    assert r["at_creases"] > 0
    # From a tenth to half a spacing (17 mm) off an edge: the other face within reach.
    gap = np.sort(np.minimum(pts, 1 - pts), axis=1)[:, 1]
    near = (gap > 0.002) & (gap < 0.0087)
    assert near.sum() > 200
    cos = np.abs(np.sum(r["normals"][near] * truth[near], axis=1))
    assert np.percentile(np.degrees(np.arccos(np.clip(cos, 0, 1))), 90) < 5
