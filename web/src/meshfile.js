// Mesh files from disk -> PUT /complex bodies. Formats: Wavefront OBJ (`v`, `f` polygons fanned
// into triangles, `l` polylines, `p` points), OFF (faces fanned; 2-index faces are segments),
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
    const n = parseInt(tok.split('/')[0], 10);
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
  int(); // edge count, unused
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

// The PUT /complex body of a file, chosen by its extension.
export function parseMeshFile(fileName, text) {
  const ext = fileName.toLowerCase().split('.').pop();
  switch (ext) {
    case 'obj': return parseObj(text, fileName);
    case 'off': return parseOff(text, fileName);
    case 'json': return parseJson(text, fileName);
    case 'txt': return parseText(text, fileName);
    default: throw new Error(`${fileName}: unknown file type ".${ext}" (OBJ, OFF, JSON or the sdlevel .txt format)`);
  }
}
