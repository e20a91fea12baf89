"""The embedded benchmark: procedural closed shapes with exact ground-truth normals (docs/algorithm.md §1.2).

It stands in for the meshes of Wang et al. 2016 in the paper's four test categories. Mesh vertex normals are
only estimates; here every normal is exact: analytic on curved pieces (from analytic partial derivatives or
the implicit gradient), the plane normal on flat ones. A shape is a union of pieces that meet only along their
boundaries (a closed surface, no internal faces, normals outward). Each piece knows its area and samples
points uniformly by area, and a shape draws each piece's share of points in proportion to its area. Every
shape is centred on its bounding box and scaled so that its farthest point is at distance 1 (exactly for
polyhedra, quadrics, lathes and prisms; to about 1e-4 for displaced surfaces, whose extent is sampled).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any, Protocol

import numpy as np

from refinenet.data.meshes import mesh_area, sample_mesh

#: The paper's four synthetic categories, in the order the catalogue lists them.
SHARP, SMOOTH, RICH, BIG_NOISE = "SharpFeature", "SmoothSurface", "RichFeature", "BigNoise"
CATEGORIES = (SHARP, SMOOTH, RICH, BIG_NOISE)
#: Column order of the paper's synthetic tables (table:synthetic_result).
TABLE_ORDER = (BIG_NOISE, SHARP, RICH, SMOOTH)

GRID = 256  # quadrature intervals per parameter of a curved piece (area and rejection bound)
RADIAL_NODES = 1 << 16  # quadrature directions of a star-shaped piece
BOUND_MARGIN = 1.05  # headroom of a rejection bound over the largest Jacobian seen on the quadrature nodes

Array = np.ndarray
SurfaceMap = Callable[[Array, Array], tuple[Array, Array, Array]]
RadiusMap = Callable[[Array], tuple[Array, Array]]
Proposal = Callable[[int, np.random.Generator], tuple[Array, Array, Array]]


class Piece(Protocol):
    """A patch of a closed surface: its area, an area-uniform sampler, and points that bound its extent."""

    area: float
    reference: Array

    def sample(self, n: int, rng: np.random.Generator) -> tuple[Array, Array]: ...


def _unit(vectors: Array) -> Array:
    return vectors / np.linalg.norm(vectors, axis=1, keepdims=True)


def _accept_reject(propose: Proposal, acceptance: float, n: int,
                   rng: np.random.Generator) -> tuple[Array, Array]:
    """The first n accepted proposals; `propose(m, rng)` gives points, unnormalised normals and acceptance
    probabilities.

    Accepting with probability proportional to the area element makes the result exactly area-uniform,
    provided no probability exceeds 1: a piece whose bound is too low is a bug, so it raises rather than bias
    the sample.
    """
    points, normals, need = [np.empty((0, 3))], [np.empty((0, 3))], n
    while need > 0:
        m = int(need / acceptance * 1.1) + 64
        p, v, prob = propose(m, rng)
        if (prob > 1).any():
            raise RuntimeError(f"rejection bound exceeded (by a factor {prob.max():.4f}): a piece is wrong")
        keep = rng.random(m) < prob
        points.append(p[keep][:need])
        normals.append(v[keep][:need])
        need -= len(points[-1])
    return np.concatenate(points), _unit(np.concatenate(normals))


class TriangleMesh:
    """Flat triangles wound outward; each point gets its face's plane normal."""

    def __init__(self, vertices: Array, faces: Array):
        self.vertices, self.faces = vertices, faces
        self.area = mesh_area(vertices, faces)
        self.reference = vertices

    def sample(self, n: int, rng: np.random.Generator) -> tuple[Array, Array]:
        return sample_mesh(self.vertices, self.faces, n, rng)


def _signed_area(loop: Array) -> float:
    x, y = loop[:, 0], loop[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


class PlanarRegion:
    """A flat face at height z: the even-odd interior of closed 2-D loops (outer one counter-clockwise, holes
    clockwise).

    Points are drawn uniformly in the bounding box and kept when inside, which is exactly uniform by area.
    """

    def __init__(self, loops: Sequence[Array], z: float, up: bool):
        # Imported here: every stage imports this module through the cloud reader, only the clouds step builds
        # shapes, and matplotlib adds about 0.1 s to the start-up of each of the pipeline's ~700 jobs.
        from matplotlib.path import Path

        self.paths = [Path(np.vstack([loop, loop[:1]]), closed=True) for loop in loops]
        self.z, self.normal = z, np.array([0.0, 0.0, 1.0 if up else -1.0])
        self.area = sum(_signed_area(loop) for loop in loops)
        corners = np.concatenate(loops)
        self.low, self.high = corners.min(axis=0), corners.max(axis=0)
        self.reference = np.column_stack([corners, np.full(len(corners), z)])

    def _propose(self, m: int, rng: np.random.Generator) -> tuple[Array, Array, Array]:
        xy = rng.uniform(self.low, self.high, (m, 2))
        inside = np.logical_xor.reduce([path.contains_points(xy) for path in self.paths])
        return np.column_stack([xy, np.full(m, self.z)]), np.tile(self.normal, (m, 1)), inside.astype(float)

    def sample(self, n: int, rng: np.random.Generator) -> tuple[Array, Array]:
        return _accept_reject(self._propose, self.area / float(np.prod(self.high - self.low)), n, rng)


class Parametric:
    """A map f(u, v) over a rectangle with analytic partials; the normal is f_u x f_v (the map's order makes
    it point outward). (u, v) uniform, accepted with probability |f_u x f_v| / bound, is exactly area-uniform.

    Area and bound come from the trapezoid rule on the node grid, which is exact for the piecewise-linear
    Jacobians of walls and lathes when the nodes include the profile's kinks.
    """

    def __init__(self, fn: SurfaceMap, u_nodes: Array, v_nodes: Array):
        self.fn, self.u_nodes, self.v_nodes = fn, u_nodes, v_nodes
        uu, vv = np.meshgrid(u_nodes, v_nodes, indexing="ij")
        p, pu, pv = fn(uu.ravel(), vv.ravel())
        jac = np.linalg.norm(np.cross(pu, pv), axis=1).reshape(uu.shape)
        self.area = float(np.trapezoid(np.trapezoid(jac, v_nodes, axis=1), u_nodes))
        self.bound = BOUND_MARGIN * float(jac.max())
        self.reference = p

    def _propose(self, m: int, rng: np.random.Generator) -> tuple[Array, Array, Array]:
        u = rng.uniform(self.u_nodes[0], self.u_nodes[-1], m)
        v = rng.uniform(self.v_nodes[0], self.v_nodes[-1], m)
        p, pu, pv = self.fn(u, v)
        cross = np.cross(pu, pv)
        return p, cross, np.linalg.norm(cross, axis=1) / self.bound

    def sample(self, n: int, rng: np.random.Generator) -> tuple[Array, Array]:
        box = (self.u_nodes[-1] - self.u_nodes[0]) * (self.v_nodes[-1] - self.v_nodes[0])
        return _accept_reject(self._propose, self.area / (self.bound * box), n, rng)


def _fibonacci_directions(n: int) -> Array:
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    theta = math.pi * (1 + math.sqrt(5)) * i
    rho = np.sqrt(1 - z * z)
    return np.column_stack([rho * np.cos(theta), rho * np.sin(theta), z])


# axes, face diagonals and corners: where quadrics and superquadrics reach their extent
_SPECIAL_DIRECTIONS = _unit(np.array([d for d in itertools.product((-1.0, 0.0, 1.0), repeat=3) if any(d)]))


class Radial:
    """A star-shaped surface p = r(s) s over unit directions s; `fn(s)` gives r and the gradient of r's
    formula in R^3.

    From F(p) = |p| - r(p / |p|): the outward normal is N = s - (I - s s^T) grad r / r and the area element is
    r^2 |N| dOmega. Directions uniform on the sphere, accepted with probability r^2 |N| / bound, are
    area-uniform.
    """

    def __init__(self, fn: RadiusMap):
        self.fn = fn
        directions = _fibonacci_directions(RADIAL_NODES)
        r, normal = self.evaluate(directions)
        density = r**2 * np.linalg.norm(normal, axis=1)
        self.area = 4 * math.pi * float(density.mean())
        self.bound = BOUND_MARGIN * float(density.max())
        r_special, _ = self.evaluate(_SPECIAL_DIRECTIONS)
        self.reference = np.concatenate([r[:, None] * directions, r_special[:, None] * _SPECIAL_DIRECTIONS])

    def evaluate(self, s: Array) -> tuple[Array, Array]:
        """Radius and unnormalised outward normal N (with N . s = 1) in directions s."""
        r, grad = self.fn(s)
        tangential = grad - np.sum(grad * s, axis=1, keepdims=True) * s
        return r, s - tangential / r[:, None]

    def _propose(self, m: int, rng: np.random.Generator) -> tuple[Array, Array, Array]:
        s = _unit(rng.standard_normal((m, 3)))
        r, normal = self.evaluate(s)
        return r[:, None] * s, normal, r**2 * np.linalg.norm(normal, axis=1) / self.bound

    def sample(self, n: int, rng: np.random.Generator) -> tuple[Array, Array]:
        return _accept_reject(self._propose, self.area / (4 * math.pi * self.bound), n, rng)


class Surface:
    """A closed surface made of pieces, normalised into the unit sphere."""

    def __init__(self, pieces: Sequence[Piece]):
        self.pieces = tuple(pieces)
        self.areas = np.array([piece.area for piece in self.pieces])
        reference = np.concatenate([piece.reference for piece in self.pieces])
        self.centre = 0.5 * (reference.min(axis=0) + reference.max(axis=0))
        self.scale = 1.0 / float(np.linalg.norm(reference - self.centre, axis=1).max())

    def sample(self, n: int, rng: np.random.Generator) -> tuple[Array, Array]:
        """n points uniform by area (shuffled, so any prefix is uniform too) and their exact unit normals."""
        counts = rng.multinomial(n, self.areas / self.areas.sum())
        parts = [piece.sample(int(k), rng) for piece, k in zip(self.pieces, counts, strict=True)]
        order = rng.permutation(n)
        points = (np.concatenate([p for p, _ in parts]) - self.centre) * self.scale
        return points[order], np.concatenate([q for _, q in parts])[order]


# ----------------------------------------------------------------------------------------------------------
# Building blocks: polylines, extrusions and solids of revolution


class _Polyline:
    """Arc-length parametrisation of a 2-D polyline; a closed one returns to its first vertex."""

    def __init__(self, vertices: Array, closed: bool):
        v = np.vstack([vertices, vertices[:1]]) if closed else np.asarray(vertices, dtype=float)
        step = np.diff(v, axis=0)
        lengths = np.hypot(step[:, 0], step[:, 1])
        self.start, self.direction = v[:-1], step / lengths[:, None]
        self.knots = np.concatenate([[0.0], np.cumsum(lengths)])
        self.length = float(self.knots[-1])

    def __call__(self, s: Array) -> tuple[Array, Array]:
        """Positions and unit tangents at arc lengths s."""
        seg = np.clip(np.searchsorted(self.knots, s, side="right") - 1, 0, len(self.start) - 1)
        return self.start[seg] + (s - self.knots[seg])[:, None] * self.direction[seg], self.direction[seg]


def _nodes(low: float, high: float, knots: Sequence[float] = ()) -> Array:
    return np.unique(np.concatenate([np.linspace(low, high, GRID + 1), knots]))


def _polar(angles: Array, radii: Array) -> Array:
    return np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])


def _rotate(xy: Array, cos: Array | float, sin: Array | float) -> Array:
    return np.column_stack([cos * xy[:, 0] - sin * xy[:, 1], sin * xy[:, 0] + cos * xy[:, 1]])


def _oriented(loop: Array, counter_clockwise: bool) -> Array:
    loop = np.asarray(loop, dtype=float)
    return loop if (_signed_area(loop) > 0) == counter_clockwise else loop[::-1]


def extrusion(outline: Array, holes: Sequence[Array] = (), height: float = 1.0,
              twist: float = 0.0) -> list[Piece]:
    """A prism over a planar profile with holes, turned by `twist` radians from bottom to top.

    Flat caps, and one side wall per loop, ruled by the profile's edges (planar when untwisted): the wall of
    edge point c at height z is (R(a z) c, z) with a = twist / height.
    """
    loops = [_oriented(outline, True)] + [_oriented(hole, False) for hole in holes]
    rate = twist / height
    pieces: list[Piece] = [PlanarRegion(loops, 0.0, up=False),
                           PlanarRegion([_rotate(loop, math.cos(twist), math.sin(twist)) for loop in loops],
                                        height, up=True)]
    for loop in loops:
        curve = _Polyline(loop, closed=True)

        def wall(s: Array, z: Array, curve: _Polyline = curve) -> tuple[Array, Array, Array]:
            c, t = curve(s)
            cos, sin = np.cos(rate * z), np.sin(rate * z)
            p = np.column_stack([_rotate(c, cos, sin), z])
            pu = np.column_stack([_rotate(t, cos, sin), np.zeros_like(z)])
            turned = rate * _rotate(np.column_stack([-c[:, 1], c[:, 0]]), cos, sin)
            pv = np.column_stack([turned, np.ones_like(z)])
            return p, pu, pv

        pieces.append(Parametric(wall, _nodes(0.0, curve.length, curve.knots), _nodes(0.0, height)))
    return pieces


def lathe(profile: Array) -> list[Piece]:
    """A solid of revolution about z. The profile (rho, z) runs from the axis at the bottom, outward, back to
    the axis at the top; each segment sweeps a disc, a cylinder or a cone band."""
    curve = _Polyline(np.asarray(profile, dtype=float), closed=False)

    def swept(theta: Array, s: Array) -> tuple[Array, Array, Array]:
        c, t = curve(s)
        cos, sin = np.cos(theta), np.sin(theta)
        p = np.column_stack([c[:, 0] * cos, c[:, 0] * sin, c[:, 1]])
        pu = np.column_stack([-c[:, 0] * sin, c[:, 0] * cos, np.zeros_like(s)])
        pv = np.column_stack([t[:, 0] * cos, t[:, 0] * sin, t[:, 1]])
        return p, pu, pv

    return [Parametric(swept, _nodes(0.0, 2 * math.pi), _nodes(0.0, curve.length, curve.knots))]


# ----------------------------------------------------------------------------------------------------------
# Shape kinds (the builders named by ShapeSpec.kind)


def blocks(heights: Sequence[Sequence[int]], xs: Sequence[float], ys: Sequence[float],
           zs: Sequence[float]) -> list[Piece]:
    """A union of boxes as a height field: column (i, j), of footprint xs[i] x ys[j], holds heights[i][j]
    cells of sizes zs. Only faces between a filled and an empty cell are kept, so there are no internal faces,
    and a column lower than its neighbour makes concave edges and corners. Columns must not touch only
    diagonally (the surface would not be a manifold)."""
    columns = np.asarray(heights)
    if columns.shape != (len(xs), len(ys)) or columns.max() > len(zs):
        raise ValueError(f"heights must be {len(xs)} x {len(ys)} cell counts of at most {len(zs)}")
    filled = np.arange(len(zs)) < columns[..., None]
    padded = np.pad(filled, 1).astype(np.int8)
    edges = [np.concatenate([[0.0], np.cumsum(sizes)]) for sizes in (xs, ys, zs)]
    quads = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        grid = np.transpose(padded, (a, b, c))
        change = grid[1:, 1:-1, 1:-1] - grid[:-1, 1:-1, 1:-1]  # +1: empty to filled along +a: faces -a
        i, j, k = np.nonzero(change)
        quad = np.empty((len(i), 4, 3))
        for corner, (db, dc) in enumerate(((0, 0), (1, 0), (1, 1), (0, 1))):  # counter-clockwise about +a
            quad[:, corner, a] = edges[a][i]
            quad[:, corner, b] = edges[b][j + db]
            quad[:, corner, c] = edges[c][k + dc]
        backward = change[i, j, k] > 0
        quad[backward] = quad[backward, ::-1]
        quads.append(quad)
    vertices, index = np.unique(np.concatenate(quads).reshape(-1, 3), axis=0, return_inverse=True)
    index = index.reshape(-1, 4)
    return [TriangleMesh(vertices, np.concatenate([index[:, [0, 1, 2]], index[:, [0, 2, 3]]]))]


def fandisk(notch: float, bevel: float, step: float, depth: float) -> list[Piece]:
    """A CAD part in the spirit of the fandisk: an extruded profile with a bevelled corner (convex edges),
    a V-notch and a step (concave edges)."""
    top = 1.8
    outline = [(0, 0), (4, 0), (4, top - bevel), (4 - bevel, top), (2.6, top), (2.1, top - notch), (1.6, top),
               (1.2, top), (1.2, top - step), (0, top - step)]
    return extrusion(np.array(outline, dtype=float), height=depth)


def shaft(radii: Sequence[float], lengths: Sequence[float]) -> list[Piece]:
    """Coaxial cylinders stacked along z (one radius: a capped cylinder); each change of radius makes one
    concave and one convex circular edge."""
    z = np.concatenate([[0.0], np.cumsum(lengths)])
    steps = [(r, h) for r, low, high in zip(radii, z[:-1], z[1:], strict=True) for h in (low, high)]
    return lathe(np.array([(0.0, 0.0), *steps, (0.0, z[-1])]))


def frustum(bottom: float, top: float, height: float) -> list[Piece]:
    """A capped truncated cone (top = 0: a cone with its apex)."""
    rim = [(top, height)] if top > 0 else []
    return lathe(np.array([(0.0, 0.0), (bottom, 0.0), *rim, (0.0, height)]))


_PHI = (1 + math.sqrt(5)) / 2
_SOLIDS = {
    "octahedron": [p for a in range(3) for p in (np.eye(3)[a], -np.eye(3)[a])],
    "icosahedron": [np.roll([0.0, y, z * _PHI], k) for k in range(3) for y in (-1, 1) for z in (-1, 1)],
    "dodecahedron": [np.array(p, dtype=float) for p in itertools.product((-1, 1), repeat=3)]
    + [np.roll([0.0, y / _PHI, z * _PHI], k) for k in range(3) for y in (-1, 1) for z in (-1, 1)],
    "cuboctahedron": [np.roll([x, y, 0.0], k) for k in range(3) for x in (-1, 1) for y in (-1, 1)],
}


def polyhedron(solid: str, stretch: float = 1.0, spikes: float = 0.0) -> list[Piece]:
    """The convex hull of a named solid's vertices with z scaled by `stretch`; `spikes` > 0 raises a pyramid
    of that height on each (triangular) hull face, giving a star polyhedron with concave edges. The pyramids
    stand in the disjoint outer normal regions of their faces, so they never intersect."""
    from scipy.spatial import ConvexHull  # imported here for the reason `PlanarRegion` gives (scipy.spatial: ~0.2 s)

    vertices = _unit(np.array(_SOLIDS[solid])) * np.array([1.0, 1.0, stretch])
    hull = ConvexHull(vertices)
    faces = hull.simplices.copy()
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    inward = np.sum(np.cross(b - a, c - a) * hull.equations[:, :3], axis=1) < 0
    faces[inward] = faces[inward, ::-1]
    if spikes > 0:
        apex = vertices[faces].mean(axis=1) + spikes * hull.equations[:, :3]
        apex_index = len(vertices) + np.arange(len(faces))
        vertices = np.concatenate([vertices, apex])
        faces = np.concatenate([np.column_stack([faces[:, k], faces[:, (k + 1) % 3], apex_index])
                                for k in range(3)])
    return [TriangleMesh(vertices, faces)]


def ellipsoid(a: float, b: float, c: float) -> list[Piece]:
    """x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 (a sphere when a = b = c)."""
    axes = np.array([a, b, c])

    def radius(s: Array) -> tuple[Array, Array]:
        q = np.sum((s / axes) ** 2, axis=1)
        return q**-0.5, -(q**-1.5)[:, None] * s / axes**2

    return [Radial(radius)]


def superquadric(a: float, b: float, c: float, exponent: int) -> list[Piece]:
    """|x/a|^p + |y/b|^p + |z/c|^p = 1 for an even p >= 4: a smooth rounded box."""
    axes, p = np.array([a, b, c]), exponent

    def radius(s: Array) -> tuple[Array, Array]:
        f = np.sum((s / axes) ** p, axis=1)
        return f ** (-1 / p), -(f ** (-1 / p - 1))[:, None] * (s / axes) ** (p - 1) / axes

    return [Radial(radius)]


def displaced_sphere(amplitude: float, frequency: float, waves: int, seed: int) -> list[Piece]:
    """r(s) = 1 + amplitude * mean_i sin(frequency d_i . s + phase_i), plane waves of seeded directions and
    phases: low frequency gives a smooth bumpy sphere, high frequency fine relief."""
    rng = np.random.default_rng(seed)
    directions, phases = _unit(rng.standard_normal((waves, 3))), rng.uniform(0.0, 2 * math.pi, waves)

    def radius(s: Array) -> tuple[Array, Array]:
        arg = frequency * s @ directions.T + phases
        gradient = amplitude * frequency / waves * np.cos(arg) @ directions
        return 1 + amplitude * np.sin(arg).mean(axis=1), gradient

    return [Radial(radius)]


def torus(major: float, minor: float, ridges: int = 0, winding: int = 0,
          amplitude: float = 0.0) -> list[Piece]:
    """A tube about the circle of radius `major` in the xy-plane, of radius
    minor * (1 + amplitude cos(ridges v + winding u)) at angles u (about z) and v (about the tube):
    a torus, or with ridges a twisted rope."""

    def tube(u: Array, v: Array) -> tuple[Array, Array, Array]:
        cu, su, cv, sv = np.cos(u), np.sin(u), np.cos(v), np.sin(v)
        phase = ridges * v + winding * u
        r = minor * (1 + amplitude * np.cos(phase))
        dr = -minor * amplitude * np.sin(phase)
        n = np.column_stack([cv * cu, cv * su, sv])
        n_u = np.column_stack([-cv * su, cv * cu, np.zeros_like(u)])
        n_v = np.column_stack([-sv * cu, -sv * su, cv])
        centre = major * np.column_stack([cu, su, np.zeros_like(u)])
        centre_u = major * np.column_stack([-su, cu, np.zeros_like(u)])
        p = centre + r[:, None] * n
        pu = centre_u + (winding * dr)[:, None] * n + r[:, None] * n_u
        pv = (ridges * dr)[:, None] * n + r[:, None] * n_v
        return p, pu, pv

    return [Parametric(tube, _nodes(0.0, 2 * math.pi), _nodes(0.0, 2 * math.pi))]


def gear(teeth: int, tooth_depth: float, hole: float, thickness: float) -> list[Piece]:
    """An extruded spur gear of tip radius 1 with trapezoid teeth and an optional 48-gon axle hole."""
    corners = (np.arange(teeth)[:, None] + np.array([0.0, 0.2, 0.45, 0.65])) * (2 * math.pi / teeth)
    radii = np.tile([1 - tooth_depth, 1.0, 1.0, 1 - tooth_depth], teeth)
    holes = [_polar(np.linspace(0, 2 * math.pi, 48, endpoint=False), np.full(48, hole))] if hole > 0 else []
    return extrusion(_polar(corners.ravel(), radii), holes, thickness)


def twisted_star(points: int, inner: float, twist_degrees: float, height: float) -> list[Piece]:
    """A star prism (outer radius 1) twisted about its axis: helical ridges and valleys, ruled walls."""
    angles = np.arange(2 * points) * (math.pi / points)
    radii = np.where(np.arange(2 * points) % 2 == 0, 1.0, inner)
    return extrusion(_polar(angles, radii), height=height, twist=math.radians(twist_degrees))


def grooved_column(grooves: int, depth: float, square: bool, radius: float, height: float) -> list[Piece]:
    """A cylinder with evenly spaced ring grooves (V-shaped or square) half a pitch wide."""
    pitch = height / grooves
    profile = [(0.0, 0.0), (radius, 0.0)]
    for centre in (np.arange(grooves) + 0.5) * pitch:
        low, high = centre - pitch / 4, centre + pitch / 4
        inner = [(radius - depth, low), (radius - depth, high)] if square else [(radius - depth, centre)]
        profile += [(radius, low), *inner, (radius, high)]
    return lathe(np.array([*profile, (radius, height), (0.0, height)]))


_BUILDERS: dict[str, Callable[..., list[Piece]]] = {
    f.__name__: f for f in (blocks, fandisk, shaft, frustum, polyhedron, ellipsoid, superquadric,
                            displaced_sphere, torus, gear, twisted_star, grooved_column)
}


# ----------------------------------------------------------------------------------------------------------
# The catalogue


@dataclass(frozen=True)
class ShapeSpec:
    """A named shape: its benchmark category and split, and the builder (`kind`) and parameters making it."""

    name: str
    category: str
    split: str
    kind: str
    params: tuple[tuple[str, Any], ...]

    def build(self) -> Surface:
        return Surface(_BUILDERS[self.kind](**dict(self.params)))


def _spec(name: str, category: str, split: str, kind: str, **params: Any) -> ShapeSpec:
    return ShapeSpec(name, category, split, kind, tuple(params.items()))


_SHARP, _SMOOTH, _RICH, _BIG = SHARP, SMOOTH, RICH, BIG_NOISE
_CATALOGUE = (
    # test shapes, each category's most varied first (runs may keep only the first few)
    _spec("fandisk_a", _SHARP, "test", "fandisk", notch=0.5, bevel=0.5, step=0.6, depth=1.6),
    _spec("lblock_a", _SHARP, "test", "blocks",
          heights=((2,), (1,)), xs=(0.6, 1.2), ys=(1.4,), zs=(0.6, 1.0)),
    _spec("cylinder_a", _SHARP, "test", "shaft", radii=(1.0,), lengths=(1.5,)),
    _spec("icosahedron_a", _SHARP, "test", "polyhedron", solid="icosahedron"),
    _spec("stepblock_a", _SHARP, "test", "blocks",
          heights=((3,), (2,), (1,)), xs=(0.7,) * 3, ys=(1.5,), zs=(0.5,) * 3),
    _spec("shaft_a", _SHARP, "test", "shaft", radii=(1.0, 0.55, 0.8), lengths=(0.5, 0.9, 0.4)),
    _spec("starocta_a", _SHARP, "test", "polyhedron", solid="octahedron", spikes=0.6),
    _spec("notchcube_a", _SHARP, "test", "blocks", heights=((2, 2), (2, 1)), xs=(1, 1), ys=(1, 1), zs=(1, 1)),
    _spec("frustum_a", _SHARP, "test", "frustum", bottom=1.0, top=0.4, height=1.3),
    _spec("channel_a", _SHARP, "test", "blocks",
          heights=((2,), (1,), (2,)), xs=(0.4, 1.0, 0.4), ys=(1.6,), zs=(0.5, 0.8)),
    _spec("sphere_a", _SMOOTH, "test", "ellipsoid", a=1.0, b=1.0, c=1.0),
    _spec("torus_a", _SMOOTH, "test", "torus", major=1.0, minor=0.35),
    _spec("ellipsoid_a", _SMOOTH, "test", "ellipsoid", a=1.0, b=0.7, c=0.45),
    _spec("bumpysphere_a", _SMOOTH, "test", "displaced_sphere",
          amplitude=0.12, frequency=3.0, waves=6, seed=11),
    _spec("superquadric_a", _SMOOTH, "test", "superquadric", a=1.0, b=1.0, c=0.8, exponent=4),
    _spec("gear_a", _RICH, "test", "gear", teeth=32, tooth_depth=0.12, hole=0.3, thickness=0.35),
    _spec("spikysphere_a", _RICH, "test", "displaced_sphere",
          amplitude=0.25, frequency=14.0, waves=24, seed=21),
    _spec("twistedstar_a", _RICH, "test", "twisted_star",
          points=6, inner=0.55, twist_degrees=90.0, height=1.6),
    _spec("ropetorus_a", _RICH, "test", "torus", major=1.0, minor=0.35, ridges=8, winding=3, amplitude=0.12),
    _spec("groovecolumn_a", _RICH, "test", "grooved_column",
          grooves=8, depth=0.12, square=False, radius=0.6, height=2.0),
    _spec("cornerstairs_n", _BIG, "test", "blocks",
          heights=((3, 2, 1), (2, 1, 0), (1, 0, 0)), xs=(0.6,) * 3, ys=(0.6,) * 3, zs=(0.6,) * 3),
    _spec("torus_n", _BIG, "test", "torus", major=1.0, minor=0.25),
    _spec("gear_n", _BIG, "test", "gear", teeth=16, tooth_depth=0.2, hole=0.35, thickness=0.5),
    _spec("frustum_n", _BIG, "test", "frustum", bottom=1.0, top=0.6, height=0.8),
    _spec("bumpysphere_n", _BIG, "test", "displaced_sphere", amplitude=0.1, frequency=4.0, waves=8, seed=31),
    _spec("twistedstar_n", _BIG, "test", "twisted_star", points=4, inner=0.5, twist_degrees=60.0, height=1.4),
    # training shapes: other instances of the same kinds
    _spec("fandisk_b", _SHARP, "train", "fandisk", notch=0.35, bevel=0.8, step=0.4, depth=1.0),
    _spec("lblock_b", _SHARP, "train", "blocks",
          heights=((3,), (1,)), xs=(0.5, 1.5), ys=(1.0,), zs=(0.5, 0.6, 0.6)),
    _spec("cylinder_b", _SHARP, "train", "shaft", radii=(1.0,), lengths=(0.7,)),
    _spec("dodecahedron_b", _SHARP, "train", "polyhedron", solid="dodecahedron"),
    _spec("stepblock_b", _SHARP, "train", "blocks",
          heights=((4,), (3,), (2,), (1,)), xs=(0.5,) * 4, ys=(1.2,), zs=(0.4,) * 4),
    _spec("shaft_b", _SHARP, "train", "shaft", radii=(0.7, 1.0, 0.45), lengths=(0.6, 0.3, 0.8)),
    _spec("staricosa_b", _SHARP, "train", "polyhedron", solid="icosahedron", spikes=0.5),
    _spec("frustum_b", _SHARP, "train", "frustum", bottom=1.0, top=0.0, height=1.4),
    _spec("channel_b", _SHARP, "train", "blocks",
          heights=((2,), (1,), (2,)), xs=(0.3, 0.6, 0.3), ys=(1.0,), zs=(0.3, 1.0)),
    # shallow edges (the normal turns by 26-65 degrees; the dodecahedron's by 63): without them the networks
    # smoothed across the test icosahedron's 42-degree edges (README "Training shapes"; studies/README.md)
    _spec("icosahedron_b", _SHARP, "train", "polyhedron", solid="icosahedron", stretch=0.6),
    _spec("torus_b", _SMOOTH, "train", "torus", major=1.0, minor=0.5),
    _spec("ellipsoid_b", _SMOOTH, "train", "ellipsoid", a=1.0, b=0.5, c=0.5),
    _spec("bumpysphere_b", _SMOOTH, "train", "displaced_sphere",
          amplitude=0.15, frequency=2.5, waves=5, seed=12),
    _spec("superquadric_b", _SMOOTH, "train", "superquadric", a=1.0, b=0.7, c=0.6, exponent=6),
    _spec("gear_b", _RICH, "train", "gear", teeth=24, tooth_depth=0.15, hole=0.0, thickness=0.5),
    _spec("spikysphere_b", _RICH, "train", "displaced_sphere",
          amplitude=0.2, frequency=18.0, waves=24, seed=22),
    _spec("twistedstar_b", _RICH, "train", "twisted_star",
          points=5, inner=0.45, twist_degrees=150.0, height=1.2),
    _spec("ropetorus_b", _RICH, "train", "torus", major=1.0, minor=0.4, ridges=6, winding=2, amplitude=0.1),
    _spec("groovecolumn_b", _RICH, "train", "grooved_column",
          grooves=6, depth=0.1, square=True, radius=0.7, height=1.8),
)


def catalogue() -> dict[str, ShapeSpec]:
    """Every embedded shape by name, in a fixed order: test shapes first, then training shapes."""
    return {spec.name: spec for spec in _CATALOGUE}


@cache
def surface(name: str) -> Surface:
    """The built (and cached) surface of a catalogued shape."""
    spec = catalogue().get(name)
    if spec is None:
        raise ValueError(f"unknown shape '{name}' (known: {', '.join(catalogue())})")
    return spec.build()


def sample_shape(name: str, n_points: int, seed: int) -> tuple[Array, Array]:
    """n_points points uniform by area on a catalogued shape and their exact outward unit normals (float64).

    The same (name, n_points, seed) gives bit-identical arrays.
    """
    if n_points < 1:
        raise ValueError(f"n_points must be >= 1, got {n_points}")
    return surface(name).sample(n_points, np.random.default_rng(seed))
