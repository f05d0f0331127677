// The built-in examples, generated here as PUT /complex bodies. Each is small (a few hundred
// simplices at most), mixes dimensions and has non-manifold junctions, and is valid for the
// daemon: no degenerate or duplicate simplices, no repeated vertex in a simplex. Solids are
// structured grids of cubes split into 6 tetrahedra each along the main diagonal (Freudenthal /
// Kuhn), which is conforming across neighbouring cubes.

class Builder {
  constructor() {
    this.vertices = [];
    this.simplices = [];
  }

  point(p) {
    this.vertices.push(p.map((x) => Math.round(x * 1e6) / 1e6));
    return this.vertices.length - 1;
  }

  add(...ids) {
    this.simplices.push(ids);
  }

  // Triangles of the quad strip between two rows of equal length.
  strip(a, b) {
    for (let i = 0; i + 1 < a.length; i++) {
      this.add(a[i], a[i + 1], b[i + 1]);
      this.add(a[i], b[i + 1], b[i]);
    }
  }

  polyline(ids) {
    for (let i = 0; i + 1 < ids.length; i++) this.add(ids[i], ids[i + 1]);
  }

  // A (nx × ny × nz)-cube grid with corners at map(i, j, k); returns id(i, j, k).
  grid(nx, ny, nz, map) {
    const ids = [];
    for (let k = 0; k <= nz; k++)
      for (let j = 0; j <= ny; j++)
        for (let i = 0; i <= nx; i++) ids.push(this.point(map(i, j, k)));
    const id = (i, j, k) => ids[(k * (ny + 1) + j) * (nx + 1) + i];
    const perms = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    for (let k = 0; k < nz; k++)
      for (let j = 0; j < ny; j++)
        for (let i = 0; i < nx; i++)
          for (const p of perms) {
            const c = [i, j, k];
            const t = [id(...c)];
            for (const axis of p) {
              c[axis] += 1;
              t.push(id(...c));
            }
            this.add(...t);
          }
    return id;
  }

  body(attributes) {
    const attrs = {};
    for (const [name, f] of Object.entries(attributes))
      attrs[name] = this.vertices.map((v) => Math.round(f(v) * 1e4) / 1e4);
    return { vertices: this.vertices, simplices: this.simplices, attributes: attrs };
  }
}

// A bracket: a solid block, a vertical fin on top and a wing out of one side (surfaces meeting
// the solid along non-manifold edges), and an antenna curve from a corner of the block.
function part() {
  const b = new Builder();
  const NX = 3;
  const block = b.grid(NX, 2, 2, (i, j, k) => [i * 0.6, j * 0.45, k * 0.35]);
  // fin: rows above the line j = 1 on the top face, swept back and narrowing
  let row = [...Array(NX + 1).keys()].map((i) => block(i, 1, 2));
  for (let r = 1; r <= 2; r++) {
    const next = [...Array(NX + 1).keys()].map((i) =>
      b.point([0.25 * r + i * 0.6 * (1 - 0.3 * r), 0.45, 0.7 + 0.38 * r]));
    b.strip(row, next);
    row = next;
  }
  // wing: rows out of the side face j = 0 along k = 1, drooping a little
  row = [...Array(NX + 1).keys()].map((i) => block(i, 0, 1));
  for (let r = 1; r <= 2; r++) {
    const next = [...Array(NX + 1).keys()].map((i) =>
      b.point([0.15 * r + i * 0.6 * (1 - 0.2 * r), -0.42 * r, 0.35 - 0.06 * r * r]));
    b.strip(next, row);
    row = next;
  }
  // antenna from the top far corner
  const c0 = block(NX, 2, 2);
  const antenna = [c0, ...[[2.1, 1.05, 0.95], [2.35, 1.3, 1.3], [2.4, 1.35, 1.75], [2.2, 1.2, 2.1]]
    .map((p) => b.point(p))];
  b.polyline(antenna);
  return b.body({
    temperature: ([x, y, z]) => 20 + 40 * x + 15 * Math.max(0, z - 0.7),
    height: ([, , z]) => z,
  });
}

// A poppet valve: a solid of revolution (head, neck, stem) on a 2 × 2-cell cross-section mapped
// onto the disc, and a helical spring curve around the stem starting on the head.
function valve() {
  const b = new Builder();
  const profile = [ // [z, radius] per layer of the solid
    [0, 0.95], [0.12, 1.05], [0.26, 0.85], [0.4, 0.42], [0.6, 0.24], [1.0, 0.22],
    [1.4, 0.22], [1.8, 0.22], [2.2, 0.22], [2.45, 0.26],
  ];
  const disc = (u, v) => [u * Math.sqrt(1 - (v * v) / 2), v * Math.sqrt(1 - (u * u) / 2)];
  const body = b.grid(2, 2, profile.length - 1, (i, j, k) => {
    const [x, y] = disc(i - 1, j - 1);
    const [z, r] = profile[k];
    return [x * r, y * r, z];
  });
  // the spring starts on the head's top rim (layer 2, at u = 1, v = 0) and winds up the stem
  const start = body(2, 1, 2);
  const turns = 5, n = 50, z0 = profile[2][0], z1 = 2.05;
  const spring = [start];
  for (let t = 1; t <= n; t++) {
    const a = (2 * Math.PI * turns * t) / n;
    const r = 0.5 + 0.35 * Math.exp(-t / 2); // from the rim in to the stem, clear of the neck
    const z = z0 + 0.15 + ((z1 - z0 - 0.15) * t) / n;
    spring.push(b.point([r * Math.cos(a), r * Math.sin(a), z]));
  }
  b.polyline(spring);
  return b.body({
    stress: ([x, y, z]) => Math.exp(-(((z - 0.4) / 0.35) ** 2)) * (1 + 0.3 * x) + 0.15 * Math.hypot(x, y),
    height: ([, , z]) => z,
  });
}

// A heart-like closed surface (a deformed UV sphere) with internal walls: a septum in the plane
// x = 0 and a wall across each half at the equator, meeting the outer surface and each other
// along non-manifold edges (four chambers).
function heart() {
  const b = new Builder();
  const NLON = 12, NLAT = 8, J = 4; // 12 meridians: 3 and 9 lie in the plane x = 0
  const sphere = (theta, phi) => [Math.sin(theta) * Math.cos(phi), Math.sin(theta) * Math.sin(phi), Math.cos(theta)];
  const north = b.point(sphere(0, 0));
  const south = b.point(sphere(Math.PI, 0));
  const ring = [];
  for (let k = 1; k < NLAT; k++) {
    const r = [];
    for (let m = 0; m < NLON; m++) r.push(b.point(sphere((k * Math.PI) / NLAT, (2 * Math.PI * m) / NLON)));
    ring.push(r);
  }
  const R = (k, m) => ring[k - 1][((m % NLON) + NLON) % NLON];
  for (let m = 0; m < NLON; m++) {
    b.add(north, R(1, m), R(1, m + 1));
    b.add(south, R(NLAT - 1, m + 1), R(NLAT - 1, m));
    for (let k = 1; k + 1 < NLAT; k++) {
      b.add(R(k, m), R(k + 1, m), R(k + 1, m + 1));
      b.add(R(k, m), R(k + 1, m + 1), R(k, m + 1));
    }
  }
  // septum rows: meridian point at y < 0 (m = 9), J - 1 inner points, meridian point at y > 0
  const septum = [];
  for (let k = 1; k < NLAT; k++) {
    const z = Math.cos((k * Math.PI) / NLAT), r = Math.sin((k * Math.PI) / NLAT);
    const row = [R(k, 9)];
    for (let j = 1; j < J; j++) row.push(b.point([0, r * (-1 + (2 * j) / J), z]));
    row.push(R(k, 3));
    septum.push(row);
  }
  for (let j = 0; j < J; j++) {
    b.add(north, septum[0][j + 1], septum[0][j]);
    b.add(south, septum[NLAT - 2][j], septum[NLAT - 2][j + 1]);
  }
  for (let k = 0; k + 1 < septum.length; k++) b.strip(septum[k], septum[k + 1]);
  // equatorial walls, one per half: a fan from a centre over the half ring and the septum chord
  const eq = NLAT / 2, chord = septum[eq - 1];
  for (const side of [-1, 1]) {
    const centre = b.point([0.45 * side, 0, 0]);
    // half ring from m = 3 (y > 0) through x·side > 0 to m = 9 (y < 0), then the chord back
    const half = [];
    for (let s = 0; s <= NLON / 2; s++) half.push(R(eq, side < 0 ? 3 + s : 3 - s));
    const loop = [...half, ...chord.slice(1, -1)];
    for (let i = 0; i < loop.length; i++) b.add(centre, loop[i], loop[(i + 1) % loop.length]);
  }
  // the heart shape: a cleft between two lobes on top, a pointed apex below, a little flatter
  b.vertices = b.vertices.map(([x, y, z]) => {
    const taper = z < 0 ? 1 + 0.75 * z : 1;
    const cleft = 0.4 * Math.exp(-((x / 0.35) ** 2)) * Math.max(0, z) ** 2;
    return [1.15 * x * taper, 0.75 * y * taper, z - cleft - 0.35 * Math.max(0, -z) ** 2]
      .map((c) => Math.round(c * 1e6) / 1e6);
  });
  return b.body({
    potential: ([x, , z]) => z + 0.6 * x,
    height: ([, , z]) => z,
  });
}

export const EXAMPLES = [
  { id: 'part', name: 'Non-manifold part: solid, fins and a curve', make: part, attribute: 'temperature' },
  { id: 'valve', name: 'Valve: solid with a spring curve', make: valve, attribute: 'stress' },
  { id: 'heart', name: 'Heart: surface with internal walls', make: heart, attribute: 'potential' },
];
