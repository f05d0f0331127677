// Mesh files from disk -> PUT /complex bodies. Formats: Wavefront OBJ (`v`, `f` polygons fanned
// into triangles, `l` polylines, `p` points), OFF (faces fanned; 2-index faces are segments),
// STL (ASCII or binary; equal points merged, in order of first use), Gmsh .msh (ASCII 2.2 and
// 4.1: points, lines, triangles, quadrangles fanned, tetrahedra; nodes in the file's order),
// JSON (a PUT /complex body as it is) and the sdlevel text format (`v`, `s`; docs/TEXT_FORMAT.md).
// Parsing errors throw with the file's line number; everything else is left to the daemon,
// whose 422 names the offending simplex.

function fail(name, line, msg) {
  throw new Error(`${name}, line ${line}: ${msg}`);
}

function numbers(name, line, words) {
  const v = words.map(Number);
  if (v.some((x) => !Number.isFinite(x))) fail(name, line, `expected numbers, got "${words.join(' ')}"`);
  return v;
}

function fan(ids, out) {
  for (let i = 1; i + 1 < ids.length; i++) out.push([ids[0], ids[i], ids[i + 1]]);
}

export function parseObj(text, name = 'OBJ') {
  const vertices = [], simplices = [];
  const lines = text.split(/\r?\n/);
  // OBJ indices are 1-based; negative ones count back from the latest vertex
  const index = (tok, ln) => {
    const t = tok.split('/')[0];
    const n = /^[+-]?\d+$/.test(t) ? Number(t) : NaN;
    if (!Number.isInteger(n) || n === 0) fail(name, ln, `bad vertex reference "${tok}"`);
    const i = n > 0 ? n - 1 : vertices.length + n;
    if (i < 0 || i >= vertices.length) fail(name, ln, `vertex ${n} is not defined yet`);
    return i;
  };
  lines.forEach((raw, k) => {
    const ln = k + 1;
    const w = raw.split('#', 1)[0].trim().split(/\s+/);
    if (!w[0]) return;
    const args = w.slice(1);
    switch (w[0]) {
      case 'v': {
        if (args.length < 3) fail(name, ln, 'a vertex needs x y z');
        vertices.push(numbers(name, ln, args.slice(0, 3)));
        break;
      }
      case 'f': {
        if (args.length < 3) fail(name, ln, 'a face needs 3 or more vertices');
        fan(args.map((t) => index(t, ln)), simplices);
        break;
      }
      case 'l': {
        const ids = args.map((t) => index(t, ln));
        for (let i = 0; i + 1 < ids.length; i++) simplices.push([ids[i], ids[i + 1]]);
        break;
      }
      case 'p':
        for (const t of args) simplices.push([index(t, ln)]);
        break;
      default: // vn, vt, g, o, s, usemtl, mtllib: not geometry of the complex
    }
  });
  if (!vertices.length) throw new Error(`${name}: no vertices`);
  return { vertices, simplices };
}

export function parseOff(text, name = 'OFF') {
  // tokens with their line numbers, comments removed
  const toks = [];
  text.split(/\r?\n/).forEach((raw, k) => {
    for (const t of raw.split('#', 1)[0].trim().split(/\s+/)) if (t) toks.push([t, k + 1]);
  });
  let p = 0;
  const next = () => {
    if (p >= toks.length) fail(name, toks.length ? toks[toks.length - 1][1] : 1, 'file ends early');
    return toks[p++];
  };
  const int = () => {
    const [t, ln] = next();
    const n = Number(t);
    if (!Number.isInteger(n) || n < 0) fail(name, ln, `expected a count or index, got "${t}"`);
    return n;
  };
  if (toks.length && /^OFF$/i.test(toks[0][0])) p++;
  const nv = int(), nf = int();
  if (p < toks.length && toks[p][1] === toks[p - 1][1]) int(); // the edge count, optional, unused
  const vertices = [], simplices = [];
  for (let i = 0; i < nv; i++) {
    const w = [next(), next(), next()];
    vertices.push(numbers(name, w[0][1], w.map((x) => x[0])));
  }
  for (let f = 0; f < nf; f++) {
    const ln = toks[p]?.[1];
    const n = int();
    const ids = [];
    for (let i = 0; i < n; i++) {
      const id = int();
      if (id >= nv) fail(name, ln, `vertex ${id} out of range (${nv} vertices)`);
      ids.push(id);
    }
    // the rest of the line may hold a colour
    while (p < toks.length && toks[p][1] === ln) p++;
    if (n === 1) simplices.push(ids);
    else if (n === 2) simplices.push(ids);
    else fan(ids, simplices);
  }
  return { vertices, simplices };
}

export function parseText(text, name = 'text') {
  const vertices = [], simplices = [];
  text.split(/\r?\n/).forEach((raw, k) => {
    const w = raw.split('#', 1)[0].trim().split(/\s+/);
    if (w[0] === 'v') vertices.push(numbers(name, k + 1, w.slice(1, 4)));
    else if (w[0] === 's') simplices.push(numbers(name, k + 1, w.slice(1)));
  });
  return { vertices, simplices };
}

export function parseJson(text, name = 'JSON') {
  let j;
  try {
    j = JSON.parse(text);
  } catch (e) {
    throw new Error(`${name}: not JSON (${e.message})`);
  }
  if (!j || typeof j !== 'object' || !Array.isArray(j.vertices))
    throw new Error(`${name}: expected a PUT /complex body with "vertices" and "simplices"`);
  return j;
}

// STL: triangles of corner coordinates; equal points (exactly equal coordinates) become one
// vertex, numbered in order of first use. An ASCII solid without its "endsolid" is cut short. Binary when the size is 84 + 50 n for the n of its
// header (an ASCII file starting "solid" can be binary too), else ASCII.
export function parseStl(data, name = 'STL') {
  const vertices = [], simplices = [], ids = new Map();
  const vertex = (x, y, z) => {
    const k = `${x},${y},${z}`;
    let i = ids.get(k);
    if (i === undefined) {
      i = vertices.length;
      ids.set(k, i);
      vertices.push([x, y, z]);
    }
    return i;
  };
  const bytes = typeof data === 'string' ? new TextEncoder().encode(data) : new Uint8Array(data);
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (bytes.byteLength >= 84 && 84 + 50 * dv.getUint32(80, true) === bytes.byteLength) {
    const n = dv.getUint32(80, true);
    for (let t = 0; t < n; t++) {
      const o = 84 + 50 * t + 12; // after the facet normal
      const xyz = [0, 1, 2].map((k) => [0, 4, 8].map((d) => dv.getFloat32(o + 12 * k + d, true)));
      if (!xyz.flat().every(Number.isFinite)) throw new Error(`${name}: triangle ${t + 1} has a coordinate that is not a finite number`);
      simplices.push(xyz.map(([x, y, z]) => vertex(x, y, z)));
    }
  } else {
    const text = typeof data === 'string' ? data : new TextDecoder().decode(bytes);
    let corners = [], open = 0, last = 0;
    text.split(/\r?\n/).forEach((raw, k) => {
      const w = raw.trim().split(/\s+/);
      if (w[0]) last = k + 1;
      if (w[0] === 'solid') open = k + 1;
      else if (w[0] === 'endsolid') open = 0;
      else if (w[0] === 'vertex') {
        if (w.length < 4) fail(name, k + 1, 'a vertex needs x y z');
        const [x, y, z] = numbers(name, k + 1, w.slice(1, 4));
        corners.push(vertex(x, y, z));
      } else if (w[0] === 'endloop' || (w[0] === 'endfacet' && corners.length)) { // "outer loop" is optional
        if (corners.length !== 3) fail(name, k + 1, `a facet has ${corners.length} vertices, not 3`);
        simplices.push(corners);
        corners = [];
      }
    });
    if (!/^\s*solid/.test(text)) throw new Error(`${name}: neither ASCII STL (no "solid" at the start) nor binary STL (size is not 84 + 50 × the triangle count of its header)`);
    // a file cut short: a facet or a solid not closed (the triangles before would pass for the mesh)
    if (corners.length) fail(name, last, 'the file ends inside a facet (cut short?)');
    if (open) fail(name, last, `the solid of line ${open} has no "endsolid" (cut short?)`);
  }
  if (!simplices.length) throw new Error(`${name}: no triangles`);
  return { vertices, simplices };
}

// Gmsh .msh, ASCII 2.2 or 4.1 ($MeshFormat, $Nodes, $Elements; other sections skipped). Element
// types: 15 point, 1 line, 2 triangle, 3 quadrangle (fanned), 4 tetrahedron; any other type is
// refused (the daemon takes simplices). Physical groups are not read here (the CLI, `subdiv refine` and
// `subdiv convert --tags-out`, reads them as tags).
export function parseMsh(data, name = 'MSH') {
  const text = typeof data === 'string' ? data : new TextDecoder().decode(new Uint8Array(data));
  const lines = text.split(/\r?\n/);
  let p = 0;
  const section = (tag) => {
    while (p < lines.length && lines[p].trim() !== tag) p++;
    if (p >= lines.length) throw new Error(`${name}: no ${tag} section`);
    p++;
  };
  const row = () => {
    while (p < lines.length && !lines[p].trim()) p++;
    if (p >= lines.length) fail(name, p, 'file ends early');
    return [lines[p++].trim().split(/\s+/).map(Number), p];
  };
  const ints = (ln, v, what) => {
    if (v.some((x) => !Number.isInteger(x))) fail(name, ln, `expected integers (${what})`);
    return v;
  };
  section('$MeshFormat');
  const [fmt, fln] = row();
  const version = fmt[0];
  if (fmt[1] === 1) fail(name, fln, 'binary .msh is not read in the browser (save it as ASCII, or convert it with `subdiv convert FILE.msh -o BODY.json` and open the JSON)');
  if (!(version >= 2 && version < 3) && version !== 4.1) fail(name, fln, `format ${version}: only 2.2 and 4.1 are read`);
  const index = new Map(), vertices = [];
  section('$Nodes');
  const node = (ln, tag, xyz) => {
    if (xyz.length < 3 || !xyz.every(Number.isFinite)) fail(name, ln, 'a node needs x y z');
    index.set(tag, vertices.length);
    vertices.push(xyz.slice(0, 3));
  };
  if (version < 3) {
    const [[n], ln0] = row();
    ints(ln0, [n], 'the node count');
    for (let i = 0; i < n; i++) {
      const [v, ln] = row();
      node(ln, v[0], v.slice(1));
    }
  } else {
    const [[blocks], ln0] = row();
    ints(ln0, [blocks], 'the block count');
    for (let b = 0; b < blocks; b++) {
      const [h, ln] = row();
      const [, , parametric, n] = ints(ln, h, 'a node block header');
      const tags = [];
      for (let i = 0; i < n; i++) tags.push(row()[0][0]);
      for (let i = 0; i < n; i++) {
        const [v, vl] = row();
        if (parametric) v.length = 3;
        node(vl, tags[i], v);
      }
    }
  }
  const SIZE = { 15: 1, 1: 2, 2: 3, 3: 4, 4: 4 };
  const simplices = [];
  const element = (ln, type, tags) => {
    if (!(type in SIZE)) fail(name, ln, `element type ${type} is not a point, line, triangle, quadrangle or tetrahedron (the daemon takes simplices; convert the mesh, e.g. with gmsh)`);
    if (tags.length < SIZE[type]) fail(name, ln, `element type ${type} needs ${SIZE[type]} nodes`);
    const ids = tags.slice(0, SIZE[type]).map((t) => {
      const i = index.get(t);
      if (i === undefined) fail(name, ln, `node ${t} is not defined`);
      return i;
    });
    if (type === 3) simplices.push([ids[0], ids[1], ids[2]], [ids[0], ids[2], ids[3]]);
    else simplices.push(ids);
  };
  section('$Elements');
  if (version < 3) {
    const [[n], ln0] = row();
    ints(ln0, [n], 'the element count');
    for (let i = 0; i < n; i++) {
      const [v, ln] = row();
      ints(ln, v, 'an element');
      element(ln, v[1], v.slice(3 + v[2]));
    }
  } else {
    const [[blocks], ln0] = row();
    ints(ln0, [blocks], 'the block count');
    for (let b = 0; b < blocks; b++) {
      const [h, ln] = row();
      const [, , type, n] = ints(ln, h, 'an element block header');
      for (let i = 0; i < n; i++) {
        const [v, el] = row();
        element(el, type, ints(el, v, 'an element').slice(1));
      }
    }
  }
  if (!vertices.length) throw new Error(`${name}: no nodes`);
  return { vertices, simplices };
}

// The extensions openFile reads as bytes (the others are text).
export const BINARY_TYPES = ['stl', 'msh'];

// The PUT /complex body of a file, chosen by its extension: data is its text, or for STL and
// .msh its bytes (an ArrayBuffer) or text.
export function parseMeshFile(fileName, data) {
  const ext = fileName.toLowerCase().split('.').pop();
  const text = () => (typeof data === 'string' ? data : new TextDecoder().decode(new Uint8Array(data)));
  switch (ext) {
    case 'obj': return parseObj(text(), fileName);
    case 'off': return parseOff(text(), fileName);
    case 'stl': return parseStl(data, fileName);
    case 'msh': return parseMsh(data, fileName);
    case 'json': return parseJson(text(), fileName);
    case 'txt': return parseText(text(), fileName);
    default: throw new Error(`${fileName}: unknown file type ".${ext}" (OBJ, OFF, STL, Gmsh .msh, JSON or the sdlevel .txt format)`);
  }
}
