"""Face chart: 63 mm IPD everywhere, portraits where the pupil table says (thesis §2.2)."""

from __future__ import annotations

import json
from importlib import resources

import numpy as np
import pytest

from phonestereo.charts import Chart, FaceChart, portraits
from phonestereo.charts.faces import portrait_reflectance
from phonestereo.errors import InputError

DATA = resources.files("phonestereo.charts") / "data" / "faces"


def test_every_face_has_63mm_ipd() -> None:
    chart = FaceChart()
    kp = chart.keypoints()["pupils"]
    assert kp.ids.shape == (16, 2) and kp.ids[:3].tolist() == [[0, 0], [0, 1], [1, 0]]
    p = kp.uv.reshape(8, 2, 2)
    ipd_mm = 1000 * np.linalg.norm(p[:, 1] - p[:, 0], axis=1)
    np.testing.assert_allclose(ipd_mm, 63.0, atol=0.1)  # brief: within 0.1 mm
    assert np.all(p[:, 0, 0] < p[:, 1, 0])  # eye 0 is the left one on the chart
    assert isinstance(chart, Chart) and chart.size_m == (1.3, 0.65)


def test_pupils_in_their_cells_and_boxes_disjoint() -> None:
    chart = FaceChart()
    boxes = chart.boxes_m
    p = chart.pupils_uv()
    col, row = np.arange(8) % 4, np.arange(8) // 4
    assert np.all(boxes[:, 0] >= col * 0.325 + 0.005 - 1e-12)
    assert np.all(boxes[:, 2] <= (col + 1) * 0.325 - 0.005 + 1e-12)
    assert np.all(boxes[:, 1] >= row * 0.325 + 0.005 - 1e-12)
    assert np.all(p[..., 0] > boxes[:, None, 0]) and np.all(p[..., 0] < boxes[:, None, 2])
    assert np.all(p[..., 1] > boxes[:, None, 1]) and np.all(p[..., 1] < boxes[:, None, 3])
    # Eye midpoints on a uniform grid: centred in the cell, at 0.42 of its height.
    mid = p.mean(axis=1)
    np.testing.assert_allclose(mid[:, 0], (col + 0.5) * 0.325, atol=1e-12)
    np.testing.assert_allclose(mid[:, 1], (row + 0.42) * 0.325, atol=1e-12)


def test_pupil_darker_than_cheek() -> None:
    # A wrong pupil table or a flipped/offset placement would put the "pupil" on skin.
    chart = FaceChart()
    p = chart.pupils_uv()
    ipd = chart.ipd_m
    offsets = np.array([[dx, dy] for dx in (-0.1, 0.0, 0.1) for dy in (0.4, 0.5)]) * ipd
    for f in range(8):
        pupil = chart.intensity(p[f]).mean()
        cheek = np.median(chart.intensity((p[f][:, None, :] + offsets).reshape(-1, 2)))
        # irises print below 0.26 reflectance, lit cheeks above 0.4: factor 2 margin
        assert pupil < 0.5 * cheek, (chart.faces[f], pupil, cheek)


def test_intensity_samples_portrait_bilinearly() -> None:
    chart = FaceChart()
    img = portrait_reflectance(chart.faces[0])
    q = np.array([[300.0, 250.0], [301.0, 250.0], [300.5, 250.0], [300.25, 250.75]])
    got = chart.intensity(chart.portrait_to_uv(0, q))
    a, b, c, d = img[250, 300], img[250, 301], img[251, 300], img[251, 301]
    expect = [a, b, (a + b) / 2, 0.25 * (0.75 * a + 0.25 * b) + 0.75 * (0.75 * c + 0.25 * d)]
    np.testing.assert_allclose(got, expect, rtol=1e-12)  # exact float64 bilinear weights


def test_background_and_outside() -> None:
    chart = FaceChart()
    vals = chart.intensity([[0.001, 0.001], [0.325, 0.2], [-0.001, 0.1], [0.5, 0.66]])
    assert vals[0] == 0.2 and vals[1] == 0.2  # corner and the gap between two cells
    assert np.isnan(vals[2:]).all()


def test_pupil_table_and_licence_shipped() -> None:
    table = json.loads((DATA / "pupils.json").read_text())
    names = sorted(table["faces"])
    assert len(names) == 8
    for name in names:
        assert (DATA / name).is_file()
        entry = table["faces"][name]
        iris = np.array(entry["pupils_px"])
        contour = np.array(entry["eye_contour_centroids_px"])
        assert 80 < entry["ipd_px"] < 140  # 600 px portraits, face ~ half the frame
        # iris centre and eye-contour centroid agree to a few pixels (measured max 8.5 px)
        assert np.linalg.norm(iris - contour, axis=1).max() < 10
    licence = (DATA / "LICENSES.md").read_text()
    assert "CC0" in licence and all(n in licence for n in names)
    assert set(portraits()) == set(names)


def test_face_selection_and_errors() -> None:
    one = FaceChart(grid=(3, 1), faces=("interfaces_047.jpg",))
    assert one.faces == ("interfaces_047.jpg",) * 3
    with pytest.raises(InputError, match="unknown portrait"):
        FaceChart(faces=("nobody.jpg",))
    with pytest.raises(InputError, match="too small"):
        FaceChart(cell_m=0.05)


def test_mediapipe_finds_pupils_where_the_chart_says() -> None:
    # End to end: render each cell at 1.5 px/mm (sRGB print values) and run FaceMesh;
    # its iris centres must land on the chart's pupils. Measured: median 0.3 mm, max 1.1 mm.
    mp = pytest.importorskip("mediapipe")
    from phonestereo.charts import reflectance_to_print

    chart = FaceChart()
    n = 1500.0  # px per metre
    cell = round(chart.cell_m * n)
    truth = chart.pupils_uv()
    errs = []
    with mp.solutions.face_mesh.FaceMesh(
        static_image_mode=True, max_num_faces=1, refine_landmarks=True
    ) as mesh:
        for f in range(8):
            col, row = f % 4, f // 4
            x = (np.arange(cell) + 0.5) / n + col * chart.cell_m
            y = (np.arange(cell) + 0.5) / n + row * chart.cell_m
            uv = np.stack(np.meshgrid(x, y), axis=-1)
            gray = np.round(255 * reflectance_to_print(chart.intensity(uv))).astype(np.uint8)
            res = mesh.process(np.ascontiguousarray(np.repeat(gray[..., None], 3, axis=-1)))
            assert res.multi_face_landmarks, chart.faces[f]
            lm = res.multi_face_landmarks[0].landmark
            q = np.array([[lm[i].x * cell, lm[i].y * cell] for i in (468, 473)])
            q = q[np.argsort(q[:, 0])] / n + [col * chart.cell_m, row * chart.cell_m]
            errs.extend(np.linalg.norm(q - truth[f], axis=1))
    errs_mm = 1000 * np.array(errs)
    assert np.median(errs_mm) < 0.6 and errs_mm.max() < 2.0
