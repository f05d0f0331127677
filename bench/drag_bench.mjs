// The drag benchmark of the web front end (docs/BENCHMARKS.md, issue 15): end-to-end update of
// a dragged control point in headless chromium — mouse move -> PATCH ?delta=3 (its answer is the
// level's delta) -> the three.js buffers written — on 10³ cubes (6000 tetrahedra) at level 3
// (1.56 M cells, 531 441 vertices).
// The page's drawing is paused while timing (Viewer.pause: moves still update the buffers);
// drawing is measured apart, after.
//
//   node bench/drag_bench.mjs [--edits N] [--sustain-s S]      (make bench-drag; part of make bench)
//
// Starts build/subdivd on a free port (SUBDIVD= to choose another binary) and Debian's chromium
// (CHROMIUM=), prints the figures and, for each goal, whether it is met.
import { chromium } from '../tests/web/node_modules/playwright-core/index.mjs';
import { spawn, execFileSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import os from 'node:os';

const REPO = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..');
const args = process.argv.slice(2);
const opt = (name, dflt) => {
  const i = args.indexOf(`--${name}`);
  return i >= 0 ? Number(args[i + 1]) : dflt;
};
const EDITS = opt('edits', 200), SUSTAIN_S = opt('sustain-s', 5);
const SUBDIVD = process.env.SUBDIVD || path.join(REPO, 'build', 'subdivd');
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';

const quantile = (xs, q) => {
  const s = [...xs].sort((a, b) => a - b);
  return s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : NaN;
};
const median = (xs) => quantile(xs, 0.5);
const f1 = (x) => (Number.isFinite(x) ? x.toFixed(1) : String(x));

// ---- the daemon ----------------------------------------------------------------------------
const daemon = spawn(SUBDIVD, ['--port', '0', '--log-level', 'warn'], { stdio: ['ignore', 'pipe', 'inherit'] });
const port = await new Promise((resolve, reject) => {
  let out = '';
  daemon.stdout.on('data', (b) => {
    out += b;
    const m = out.match(/127\.0\.0\.1:(\d+)/);
    if (m) resolve(Number(m[1]));
  });
  daemon.on('exit', (c) => reject(new Error(`subdivd exited (${c}) before listening: ${out}`)));
});
const url = `http://127.0.0.1:${port}/`;
const dataDir = path.join(REPO, 'build', 'bench-data');
fs.mkdirSync(dataDir, { recursive: true });
const meshFile = path.join(dataDir, 'cubes10.txt');
fs.writeFileSync(meshFile, execFileSync('/usr/bin/python3', [path.join(REPO, 'bench', 'make_mesh.py'), 'cubes', '10'], { encoding: 'utf8' }));

const browser = await chromium.launch({
  executablePath: CHROMIUM, headless: true, args: ['--no-sandbox', '--disable-background-networking'],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  await page.goto(url);
  const idle = (extra = 'true', timeout = 120000) => page.waitForFunction(
    `window.subdivd && window.subdivd.ready && window.subdivd.idle() && (${extra})`, null, { timeout });
  await idle('window.subdivd.snapshot().shown');
  await page.evaluate(() => performance.setResourceTimingBufferSize(1e6));
  await page.setInputFiles('#file', meshFile);
  await idle(`window.subdivd.snapshot().model === 'cubes10.txt'`);
  await page.focus('#level');
  await page.keyboard.press('End');
  await idle('window.subdivd.snapshot().shown.level === 3');
  const lvl = await page.evaluate(() => {
    const s = window.subdivd.snapshot();
    return { cells: s.shown.stats.counts.tetrahedra + s.shown.stats.counts.octahedra, vertices: s.shown.stats.counts.vertices,
      bytes: s.shown.bytes, ms: s.shown.ms, build_s: s.shown.stats.seconds };
  });

  // a control point on the front of the block, near the middle of the view
  const pick = await page.evaluate(() => {
    const app = window.subdivd, v = app.viewer, r = v.canvas.getBoundingClientRect();
    let best = null;
    app.model.complex.vertices.forEach((_, i) => {
      const p = app.screenOf([i]);
      const d = Math.hypot(p.x - (r.left + r.width / 2), p.y - (r.top + r.height / 2));
      if ((!best || d < best.d) && v.vertexAt(p.x - r.left, p.y - r.top, 12) === i) best = { i, x: p.x, y: p.y, d };
    });
    return best;
  });
  if (!pick) throw new Error('no pickable control point');
  const updates = () => page.evaluate(() => window.subdivd.perf.updates.length);
  const at = (k) => ({ x: pick.x + 14 * Math.cos(0.37 * k) - 14, y: pick.y + 14 * Math.sin(0.37 * k) });

  await page.evaluate(() => window.subdivd.viewer.pause());
  await page.mouse.move(pick.x, pick.y);
  await page.mouse.down(); // the pick (a ray against the surface) is not timed
  const n0 = await updates();
  const t0res = await page.evaluate(() => performance.now());

  // 1. one move at a time: the first edit after the build, then EDITS more
  for (let k = 1; k <= EDITS + 1; k++) {
    const p = at(k);
    // the page says when the update is in (a promise: no polling, which would compete for the
    // 2 cores while the update is timed), then waits until nothing is under way
    const done = page.evaluate((n) => window.subdivd.whenUpdates(n).then(() => new Promise((r) => {
      const f = () => (window.subdivd.idle() ? r() : setTimeout(f, 1));
      f();
    })), n0 + k);
    await page.mouse.move(p.x, p.y);
    await done;
  }
  const seq = await page.evaluate(([n0, t0]) => {
    const u = window.subdivd.perf.updates.slice(n0);
    const res = performance.getEntriesByType('resource').filter((e) => e.startTime >= t0);
    const sum = (re, k) => res.filter((e) => re.test(e.name)).reduce((a, e) => a + e[k], 0);
    const phases = (re) => {
      const es = res.filter((e) => re.test(e.name));
      const med = (xs) => { const q = [...xs].sort((a, b) => a - b); return q[q.length >> 1]; };
      return { wait: med(es.map((e) => e.requestStart - e.startTime)), server: med(es.map((e) => e.responseStart - e.requestStart)),
        body: med(es.map((e) => e.responseEnd - e.responseStart)), total: med(es.map((e) => e.duration)) };
    };
    return { u, patchNet: phases(/control-points/), deltaNet: phases(/\/delta\?/), deltaBody: sum(/\/delta\?/, 'encodedBodySize'), deltaWire: sum(/\/delta\?/, 'transferSize'),
      patchBody: sum(/control-points/, 'encodedBodySize'), patchWire: sum(/control-points/, 'transferSize'),
      nDelta: res.filter((e) => /\/delta\?/.test(e.name)).length, nPatch: res.filter((e) => /control-points/.test(e.name)).length,
      full: res.filter((e) => /\/levels\/\d+(\?|$)/.test(e.name)).length };
  }, [n0, t0res]);
  const lat = seq.u.map((x) => x.applied - x.move);
  const first = lat[0], rest = lat.slice(1);
  const parts = {
    queue: median(seq.u.slice(1).map((x) => x.sent - x.move)),
    patch: median(seq.u.slice(1).map((x) => x.patched - x.sent)),
    delta: median(seq.u.slice(1).map((x) => x.applied - x.patched)),
  };
  const points = seq.u.reduce((a, x) => a + x.points, 0);
  const reqBytes = seq.u.length * JSON.stringify({ moves: [{ index: pick.i, position: [1.2345678901234567, 1.2345678901234567, 1.2345678901234567] }] }).length;

  // 2. sustained: pointer moves every 4 ms (250 Hz, dispatched in the page: playwright's mouse
  // waits for each event's acknowledgement, far slower) for SUSTAIN_S; the page coalesces
  const n1 = await updates();
  const sus = await page.evaluate(async ([n1, sec, x0, y0]) => {
    const app = window.subdivd, c = app.viewer.canvas;
    const type = 'onpointerrawupdate' in window ? 'pointerrawupdate' : 'pointermove';
    const t0 = performance.now();
    let moves = 0;
    await new Promise((done) => {
      const id = setInterval(() => {
        const k = moves++;
        c.dispatchEvent(new PointerEvent(type, { clientX: x0 + 14 * Math.cos(0.37 * k) - 14, clientY: y0 + 14 * Math.sin(0.37 * k), pointerId: 1, bubbles: true }));
        if (performance.now() - t0 > sec * 1000) {
          clearInterval(id);
          done();
        }
      }, 4);
    });
    const tEnd = performance.now();
    while (!app.idle()) await new Promise((r) => setTimeout(r, 2));
    const u = app.perf.updates.slice(n1).filter((x) => x.applied <= tEnd);
    return { n: u.length, ms: tEnd - t0, moves, lat: u.map((x) => x.applied - x.move) };
  }, [n1, SUSTAIN_S, pick.x, pick.y]);
  const moves = sus.moves;
  await page.mouse.up();

  // 2b. the floor: the same edit and delta from the page's JS alone (the page's event stream
  // closed first): as the one request the app sends (PATCH ?delta=3), and as two (PATCH, GET
  // /delta)
  const floor = await page.evaluate(async ([i, n]) => {
    window.subdivd.events.close(); // the page would follow each of these edits meanwhile
    const s = window.subdivd.session, base = `/v1/sessions/${s.id}`, auth = { Authorization: `Bearer ${s.token}` };
    let v = s.version;
    const out = { one: [], two: [] };
    const p0 = window.subdivd.model.complex.vertices[i];
    const patch = (k, q) => fetch(`${base}/control-points${q}`, { method: 'PATCH', headers: { ...auth, 'Content-Type': 'application/json', 'If-Match': `"${v}"` },
      body: JSON.stringify({ moves: [{ index: i, position: [p0[0] + 0.001 * (k % 7), p0[1], p0[2]] }] }) });
    for (let k = 0; k < 2 * n; k++) {
      const t = performance.now();
      if (k % 2) {
        const nv = (await (await patch(k, '')).json()).version;
        await (await fetch(`${base}/levels/3/delta?since=${v}&format=bin`, { headers: auth })).arrayBuffer();
        v = nv;
        out.two.push(performance.now() - t);
      } else {
        const buf = await (await patch(k, '?delta=3')).arrayBuffer();
        v = new DataView(buf).getUint32(12, true);
        out.one.push(performance.now() - t);
      }
    }
    // put the page back in step (its buffers are behind by n edits: deltas bring them)
    window.subdivd.known = v;
    await window.subdivd.requestSync();
    return out;
  }, [pick.i, 50]);

  // 3. drawing, apart: an update's buffers uploaded and drawn (render + gl.finish), 20 times
  const draw = await page.evaluate(async (p) => {
    const app = window.subdivd, v = app.viewer, gl = v.renderer.getContext(), out = [];
    for (let k = 0; k < 20; k++) {
      const n = app.perf.updates.length;
      app.queueMove(0, p.i, app.model.complex.vertices[p.i].map((x, c) => x + (c === 0 ? 0.01 : 0)));
      while (app.perf.updates.length === n || !app.idle()) await new Promise((r) => setTimeout(r, 1));
      const t = performance.now();
      v.render();
      gl.finish();
      out.push(performance.now() - t);
    }
    v.resume();
    return out;
  }, pick);

  const med = median(rest), p90 = quantile(rest, 0.9);
  const rate = sus.n / (sus.ms / 1000);
  // the deltas' bodies, wherever they came (in the PATCH answers, PATCH ?delta=, or GET /delta)
  const deltaBody = seq.u.reduce((a, x) => a + x.bytes, 0);
  const perPoint = deltaBody / points;
  const wirePerPoint = (seq.deltaWire + seq.patchWire + reqBytes) / points;
  const goals = [
    ['median update <= 16 ms', med <= 16, `${f1(med)} ms`],
    ['sustained >= 50 updates/s', rate >= 50, `${f1(rate)} updates/s`],
    ['delta bytes per changed point <= 32', perPoint <= 32, `${f1(perPoint)} B`],
    ['first edit after the build within 3x the median', first <= 3 * med, `${f1(first)} ms = ${f1(first / med)}x`],
  ];
  console.log(`== drag in headless chromium: 10³ cubes (6000 tetrahedra) at level 3: ${lvl.cells} cells, ${lvl.vertices} vertices`);
  console.log(`level 3 fetched once: ${(lvl.bytes / 1e6).toFixed(1)} MB GLB in ${Math.round(lvl.ms)} ms (build ${f1(lvl.build_s * 1000)} ms)`);
  console.log(`${rest.length} edits one at a time (mouse move -> PATCH -> delta -> buffers; drawing paused):`);
  console.log(`  median ${f1(med)} ms, p90 ${f1(p90)} ms, min ${f1(Math.min(...rest))} ms, max ${f1(Math.max(...rest))} ms`);
  console.log(`  of which (medians): event to PATCH sent ${f1(parts.queue)} ms, PATCH ${f1(parts.patch)} ms, delta + buffers ${f1(parts.delta)} ms`);
  const ph = (x) => `queued ${f1(x.wait)}, to first byte ${f1(x.server)}, body ${f1(x.body)}, whole ${f1(x.total)} ms`;
  console.log(`  network (resource timing medians): PATCH ${ph(seq.patchNet)}` + (seq.nDelta ? `; delta ${ph(seq.deltaNet)}` : ' (its answer is the delta)'));
  const u0 = seq.u[0];
  console.log(`  first edit after the build: ${f1(first)} ms (${f1(first / med)}x the median): event to PATCH sent ${f1(u0.sent - u0.move)}, ` +
    `PATCH ${f1(u0.patched - u0.sent)}, delta + buffers ${f1(u0.applied - u0.patched)} ms`);
  console.log(`  ${seq.nPatch} PATCH, ${seq.nDelta} deltas, ${seq.full} level downloads; ${f1(points / seq.u.length)} changed points per edit`);
  console.log(`  bytes per edit: delta body ${f1(deltaBody / seq.u.length)} = ${f1(perPoint)} per changed point (32 x points = ${f1(32 * points / seq.u.length)}); ` +
    `on the wire with headers, PATCH both ways included: ${f1((seq.deltaWire + seq.patchWire + reqBytes) / seq.u.length)} = ${f1(wirePerPoint)} per point`);
  console.log(`  floor: the same PATCH ?delta=3 (one request) from the page's JS alone, no app code: median ${f1(median(floor.one))} ms, p90 ${f1(quantile(floor.one, 0.9))} ms`);
  console.log(`  … and as two requests (PATCH, then GET /delta): median ${f1(median(floor.two))} ms, p90 ${f1(quantile(floor.two, 0.9))} ms`);
  console.log(`sustained for ${SUSTAIN_S} s: ${moves} pointer moves (250 Hz) -> ${sus.n} updates = ${f1(rate)} updates/s (latency median ${f1(median(sus.lat))} ms, p90 ${f1(quantile(sus.lat, 0.9))} ms)`);
  console.log(`drawing, apart: an updated frame uploaded and drawn (render + gl.finish): median ${f1(median(draw))} ms, p90 ${f1(quantile(draw, 0.9))} ms (software GL here)`);
  console.log(`machine: ${os.cpus().length} cores, load average ${os.loadavg().map((x) => x.toFixed(1)).join(' ')} at the end (the daemon, chromium's processes and this driver share them)`);
  for (const [g, ok, v] of goals) console.log(`goal ${g}: ${v} — ${ok ? 'met' : 'NOT met'}`);
  if (errors.length) console.log(`page errors: ${errors.join(' | ')}`);
} finally {
  await browser.close();
  daemon.kill('SIGTERM');
}
