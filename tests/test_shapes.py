"""Procedural shapes: catalogue rules, exact normals, area-uniform sampling, closed outward surfaces."""

import math
import re
from collections import Counter

import numpy as np
import pytest
from scipy import integrate
from scipy.spatial import cKDTree

from refinenet.data import shapes
from refinenet.data.shapes import (
    CATEGORIES,
    Parametric,
    Radial,
    Surface,
    TriangleMesh,
    blocks,
    ellipsoid,
    extrusion,
    frustum,
    sample_shape,
    shaft,
    torus,
)

CATALOGUE = shapes.catalogue()
NAMES = list(CATALOGUE)
MIN_TEST = {"SharpFeature": 6, "SmoothSurface": 4, "RichFeature": 4, "BigNoise": 4}
MIN_TRAIN = {"SharpFeature": 4, "SmoothSurface": 4, "RichFeature": 4, "BigNoise": 0}
CHI2_P001 = {3: 16.27, 5: 20.52}  # chi-square quantiles at p = 0.001 by degrees of freedom


def sample(surface: Surface, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    return surface.sample(n, np.random.default_rng(seed))


def chi_square(counts: np.ndarray, weights: np.ndarray) -> float:
    expected = counts.sum() * np.asarray(weights, dtype=float) / np.sum(weights)
    return float(np.sum((counts - expected) ** 2 / expected))


def within_sigmas(share: float, p: float, n: int, sigmas: float = 4.0) -> bool:
    return abs(share - p) < sigmas * math.sqrt(p * (1 - p) / n)


# ---- catalogue -----------------------------------------------------------------------------------------


def test_catalogue_meets_the_category_minimums():
    count = Counter((spec.split, spec.category) for spec in CATALOGUE.values())
    for category in CATEGORIES:
        assert count["test", category] >= MIN_TEST[category], category
        assert count["train", category] >= MIN_TRAIN[category], category
    assert count["train", "BigNoise"] == 0


def test_names_are_unique_valid_and_in_a_fixed_order():
    assert list(shapes.catalogue()) == NAMES
    for name, spec in CATALOGUE.items():
        assert spec.name == name and re.fullmatch(r"[a-z0-9_]+", name)
        assert spec.category in CATEGORIES and spec.split in ("train", "test")


def _descriptor(name: str) -> np.ndarray:
    """Area and bounding box after normalisation: equal for equal (or merely rescaled) geometry."""
    surface = shapes.surface(name)
    reference = (np.concatenate([piece.reference for piece in surface.pieces]) - surface.centre) * surface.scale
    return np.concatenate([[surface.areas.sum() * surface.scale**2], np.ptp(reference, axis=0)])


def test_training_shapes_never_repeat_a_test_geometry():
    train = [s for s in CATALOGUE.values() if s.split == "train"]
    test = [s for s in CATALOGUE.values() if s.split == "test"]
    assert not {(s.kind, s.params) for s in train} & {(s.kind, s.params) for s in test}
    descriptors = {name: _descriptor(name) for name in NAMES}
    for a in train:
        for b in test:
            assert np.abs(descriptors[a.name] - descriptors[b.name]).max() > 1e-3, (a.name, b.name)


# ---- every shape ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_every_shape_is_a_closed_outward_unit_surface(name):
    n = 20_000
    points, normals = sample_shape(name, n, seed=1)
    assert points.shape == normals.shape == (n, 3) and points.dtype == normals.dtype == np.float64
    assert np.isfinite(points).all()
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    radius = np.linalg.norm(points, axis=1)
    assert 0.95 < radius.max() <= 1 + 1e-3
    assert np.abs(points.max(axis=0) + points.min(axis=0)).max() < 0.05  # centred on its bounding box
    # a closed surface has zero mean normal (integral of n dA = 0): a missing or flipped piece breaks it
    standard_error = normals.std(axis=0) / math.sqrt(n)
    assert (np.abs(normals.mean(axis=0)) < 5 * standard_error + 1e-12).all()
    # the integral of p . n dA is 3 x volume > 0 when normals point outward
    assert np.mean(np.sum(points * normals, axis=1)) > 0.1


def test_normals_are_perpendicular_to_the_surface():
    """Analytic partials and radius gradients against central differences, on every curved piece."""
    rng, h = np.random.default_rng(3), 1e-6
    for name in NAMES:
        for piece in shapes.surface(name).pieces:
            if isinstance(piece, Parametric):
                u = rng.uniform(piece.u_nodes[0], piece.u_nodes[-1], 400)
                v = rng.uniform(piece.v_nodes[0], piece.v_nodes[-1], 400)
                away = (np.abs(u[:, None] - piece.u_nodes).min(axis=1) > 1e-4) & \
                       (np.abs(v[:, None] - piece.v_nodes).min(axis=1) > 1e-4)
                u, v = u[away], v[away]
                _, pu, pv = piece.fn(u, v)
                np.testing.assert_allclose((piece.fn(u + h, v)[0] - piece.fn(u - h, v)[0]) / (2 * h), pu,
                                           atol=1e-6, err_msg=name)
                np.testing.assert_allclose((piece.fn(u, v + h)[0] - piece.fn(u, v - h)[0]) / (2 * h), pv,
                                           atol=1e-6, err_msg=name)
            elif isinstance(piece, Radial):
                s = rng.standard_normal((400, 3))
                s /= np.linalg.norm(s, axis=1, keepdims=True)
                _, grad = piece.fn(s)
                for k in range(3):
                    step = h * np.eye(3)[k]
                    np.testing.assert_allclose((piece.fn(s + step)[0] - piece.fn(s - step)[0]) / (2 * h),
                                               grad[:, k], atol=1e-6, err_msg=name)


def test_rejection_bounds_hold_on_dense_random_parameters():
    rng = np.random.default_rng(4)
    for name in NAMES:
        for piece in shapes.surface(name).pieces:
            if isinstance(piece, Parametric):
                m = 100_000
                u = rng.uniform(piece.u_nodes[0], piece.u_nodes[-1], m)
                v = rng.uniform(piece.v_nodes[0], piece.v_nodes[-1], m)
                _, pu, pv = piece.fn(u, v)
                density = np.linalg.norm(np.cross(pu, pv), axis=1)
            elif isinstance(piece, Radial):
                s = rng.standard_normal((100_000, 3))
                r, normal = piece.evaluate(s / np.linalg.norm(s, axis=1, keepdims=True))
                density = r**2 * np.linalg.norm(normal, axis=1)
            else:
                continue
            assert density.max() <= piece.bound, name


def test_polyhedral_pieces_are_closed_and_consistently_wound():
    """Every directed edge of a closed, outward-wound mesh appears once, and so does its reverse."""
    for name in NAMES:
        for piece in shapes.surface(name).pieces:
            if isinstance(piece, TriangleMesh):
                edges = np.concatenate([piece.faces[:, [0, 1]], piece.faces[:, [1, 2]], piece.faces[:, [2, 0]]])
                directed = Counter(map(tuple, edges))
                assert max(directed.values()) == 1, name
                assert all((b, a) in directed for a, b in directed), name


def test_same_name_size_and_seed_give_identical_arrays():
    first, second = sample_shape("gear_a", 3000, 5), sample_shape("gear_a", 3000, 5)
    assert np.array_equal(first[0], second[0]) and np.array_equal(first[1], second[1])
    assert not np.array_equal(first[0], sample_shape("gear_a", 3000, 6)[0])


def test_bad_requests_raise_clear_errors():
    with pytest.raises(ValueError, match="unknown shape 'teapot'"):
        sample_shape("teapot", 100, 0)
    with pytest.raises(ValueError, match="n_points must be >= 1"):
        sample_shape("sphere_a", 0, 0)
    with pytest.raises(ValueError, match="heights must be 2 x 1"):
        blocks(((1, 1),), (1.0, 1.0), (1.0,), (1.0,))


# ---- shapes with known answers -------------------------------------------------------------------------


def test_sphere_points_and_normals_are_exact_and_zones_follow_archimedes():
    n = 40_000
    points, normals = sample_shape("sphere_a", n, seed=2)
    radius = np.linalg.norm(points, axis=1)
    np.testing.assert_allclose(radius, 1.0, atol=1e-12)
    np.testing.assert_allclose(normals, points / radius[:, None], atol=1e-12)
    # a zone between two parallel planes has area proportional to its height: z in [0.2, 0.7] -> 1/4
    assert within_sigmas(np.mean((points[:, 2] > 0.2) & (points[:, 2] < 0.7)), 0.25, n)
    assert shapes.surface("sphere_a").areas.sum() == pytest.approx(4 * math.pi, rel=1e-12)


def test_ellipsoid_normals_are_the_implicit_gradient():
    surface = Surface(ellipsoid(3.0, 2.0, 1.0))
    points, normals = sample(surface, 20_000)
    axes = np.array([3.0, 2.0, 1.0]) * surface.scale
    np.testing.assert_allclose(np.sum((points / axes) ** 2, axis=1), 1.0, atol=1e-12)
    gradient = points / axes**2
    np.testing.assert_allclose(normals, gradient / np.linalg.norm(gradient, axis=1, keepdims=True), atol=1e-12)


def test_spheroid_zone_area_matches_quadrature():
    a, c, n = 2.0, 1.0, 60_000
    surface = Surface(ellipsoid(a, a, c))
    points, _ = sample(surface, n, seed=3)

    def ring(z: float) -> float:  # 2 pi rho ds/dz for rho(z) = a sqrt(1 - z^2/c^2)
        return 2 * math.pi * math.sqrt(a**2 * (1 - z**2 / c**2) + a**4 * z**2 / c**4)

    total = integrate.quad(ring, -c, c)[0]
    share = integrate.quad(ring, c / 2, c)[0] / total
    assert surface.areas.sum() == pytest.approx(total, rel=1e-6)
    assert within_sigmas(np.mean(points[:, 2] > c / 2 * surface.scale), share, n)


def test_torus_points_normals_and_outer_to_inner_area_ratio():
    major, minor, n = 1.0, 0.4, 40_000
    surface = Surface(torus(major, minor))
    points, normals = sample(surface, n, seed=4)
    big, small = major * surface.scale, minor * surface.scale
    rho = np.hypot(points[:, 0], points[:, 1])
    np.testing.assert_allclose((rho - big) ** 2 + points[:, 2] ** 2, small**2, atol=1e-12)
    expected = np.column_stack([(rho - big) * points[:, 0] / rho, (rho - big) * points[:, 1] / rho,
                                points[:, 2]]) / small
    np.testing.assert_allclose(normals, expected, atol=1e-12)
    # dA = r (R + r cos v) du dv: the outer half (cos v > 0) has 2 pi r (pi R + 2 r), the inner 2 pi r (pi R - 2 r)
    assert within_sigmas(np.mean(rho > big), 0.5 + minor / (math.pi * major), n)
    assert surface.areas.sum() == pytest.approx(4 * math.pi**2 * major * minor, rel=1e-9)


def test_box_points_lie_on_faces_with_axis_normals_in_area_proportion():
    n = 30_000
    surface = Surface(blocks(((1,),), (2.0,), (1.0,), (0.5,)))
    points, normals = sample(surface, n, seed=5)
    half = np.array([1.0, 0.5, 0.25]) * surface.scale
    axis = np.argmax(np.abs(normals), axis=1)
    sign = normals[np.arange(n), axis]
    assert np.isin(sign, (-1.0, 1.0)).all() and (np.abs(normals).sum(axis=1) == 1.0).all()
    np.testing.assert_allclose(points[np.arange(n), axis], sign * half[axis], atol=1e-12)
    assert (np.abs(points) <= half + 1e-12).all()
    counts = np.bincount(2 * axis + (sign > 0), minlength=6)
    assert chi_square(counts, [0.5, 0.5, 1.0, 1.0, 2.0, 2.0]) < CHI2_P001[5]


def test_prism_with_a_hole_samples_caps_and_both_walls_by_area():
    n = 30_000
    square = np.array([[-1.0, -1], [1, -1], [1, 1], [-1, 1]])
    surface = Surface(extrusion(square, holes=[0.5 * square], height=0.5))
    np.testing.assert_allclose(surface.areas, [3.0, 3.0, 4.0, 2.0], rtol=1e-12)  # caps, outer and inner walls
    points, normals = sample(surface, n, seed=6)
    x, y = (points[:, :2] / surface.scale).T
    ring = np.maximum(np.abs(x), np.abs(y))
    cap = np.abs(normals[:, 2]) == 1.0
    assert (ring[cap] >= 0.5 - 1e-12).all()  # nothing in the hole
    outward = np.sum(normals[:, :2] * np.column_stack([x, y]), axis=1)
    outer_wall, inner_wall = ~cap & (outward > 0), ~cap & (outward < 0)
    np.testing.assert_allclose(ring[outer_wall], 1.0, atol=1e-12)
    np.testing.assert_allclose(ring[inner_wall], 0.5, atol=1e-12)
    counts = np.array([np.sum(normals[:, 2] == -1), np.sum(normals[:, 2] == 1), outer_wall.sum(), inner_wall.sum()])
    assert counts.sum() == n and chi_square(counts, surface.areas) < CHI2_P001[3]


def test_capped_cylinder_and_cone_normals_and_area_split():
    n = 30_000
    cylinder = Surface(shaft((1.0,), (2.0,)))
    points, normals = sample(cylinder, n, seed=7)
    side = normals[:, 2] == 0
    rho = np.hypot(points[:, 0], points[:, 1])
    np.testing.assert_allclose(rho[side], cylinder.scale, atol=1e-12)
    np.testing.assert_allclose(normals[side, :2], points[side, :2] / rho[side, None], atol=1e-12)
    assert np.isin(normals[~side, 2], (-1.0, 1.0)).all() and (normals[~side, :2] == 0).all()
    assert within_sigmas(side.mean(), 4 / 6, n)  # side 2 pi r h = 4 pi, caps pi each

    cone = Surface(frustum(1.0, 0.0, 1.0))
    points, normals = sample(cone, n, seed=8)
    lateral = normals[:, 2] > 0
    rho = np.hypot(points[:, 0], points[:, 1])
    expected = np.column_stack([points[:, :2] / rho[:, None], np.ones(n)]) / math.sqrt(2)
    np.testing.assert_allclose(normals[lateral], expected[lateral], atol=1e-12)
    assert within_sigmas(lateral.mean(), math.sqrt(2) / (math.sqrt(2) + 1), n)  # pi r l : pi r^2


def _perpendicular_pairs(points: np.ndarray, normals: np.ndarray, radius: float):
    """Pairs of nearby points with perpendicular normals, split into concave and convex configurations."""
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    i, j = pairs[np.abs(np.sum(normals[pairs[:, 0]] * normals[pairs[:, 1]], axis=1)) < 1e-9].T
    gap = points[j] - points[i]
    # concave: each point lies on the outer side of the other's tangent plane
    concave = (np.sum(gap * normals[i], axis=1) > 0) & (np.sum(-gap * normals[j], axis=1) > 0)
    return (points[i] + points[j])[concave] / 2, (points[i] + points[j])[~concave] / 2


def test_l_prism_has_a_concave_edge_exactly_where_the_profile_turns_inward():
    # columns x in [0, 1] of height 2 and x in [1, 2] of height 1: the concave edge runs along y at x = z = 1,
    # which normalisation (bounding-box centre (1, 0.5, 1)) moves to x = z = 0
    surface = Surface(blocks(((2,), (1,)), (1.0, 1.0), (1.0,), (1.0, 1.0)))
    radius = 0.04
    concave, convex = _perpendicular_pairs(*sample(surface, 20_000, seed=9), radius)
    assert len(concave) > 20 and len(convex) > 20
    assert (np.abs(concave[:, [0, 2]]) < radius).all()
    box_concave, _ = _perpendicular_pairs(*sample(Surface(blocks(((1,),), (1.0,), (1.0,), (1.0,))), 20_000), radius)
    assert len(box_concave) == 0
