// The subdivd front end: the panel, the tools and the conversation with the daemon.
//
// Every request of the session goes through App.run(), one after the other, so versions stay
// consistent (a PATCH sends the version the previous answer reported as If-Match). Level fetches
// and point moves are coalesced: while one is under way, later wishes collapse into one more
// round (requestLevel, queueMove), which is what lets a dragged point and the level slider follow
// the mouse without a backlog. Every failure ends up in App.error(), shown in words.
//
// The live loop (API.md "Live edits"): a move is a PATCH (at most one in flight; the latest
// position of each point wins), then a delta of the shown level since the version its buffers
// hold, written into them in place — no level download and no stats request per move. The
// session's /events stream (EventSource, ?access_token=) tells of changes made elsewhere (another
// tab): edits are followed by deltas (the cage's by a JSON delta of level 0, exact), anything
// else by fetching the complex and the level again, as is a delta answered 410.
import './style.css';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import * as THREE from 'three';
import { Session, ApiError, TTL_S } from './api.js';
import { EXAMPLES } from './examples.js';
import { parseMeshFile, BINARY_TYPES } from './meshfile.js';
import { Viewer } from './viewer.js';
import { RULE_NAMES, RULE_DESCRIPTIONS, ruleFamily, ruleHex, viridisCss, sharpnessCss } from './colors.js';

const $ = (id) => document.getElementById(id);
const FIRST_LEVEL = 2;
const MAX_LEVEL = 6;
const MAX_CELLS = 2e6; // the slider stops before a level would have more top cells than this

const TOOL_HINTS = {
  move: 'Drag a round control point to reshape it · slide the level · tag creases with the tools on the left',
  corner: 'Click a control vertex to tag it as a corner of the sharpness set in the panel (click again to untag)',
  crease: 'Click a control edge to tag it as a crease of the sharpness set in the panel (click again to untag)',
  surface: 'Click a control triangle to tag it as an embedded surface of the sharpness set in the panel (click again to untag)',
  rule: 'Click a control vertex or edge, then choose its non-manifold rule in the panel',
};

const key = (s) => [...s].sort((a, b) => a - b).join(',');

// What a PUT /tags must send to keep every tag the complex has (a PUT replaces them all).
function tagsOf(complex) {
  const t = complex.tags || {};
  const out = { singular: (t.singular || []).map((s) => [...s]) };
  if (t.petals?.length) out.petals = t.petals.map((p) => ({ ...p }));
  if (t.sharpness?.length) out.sharpness = t.sharpness.map((e) => ({ simplex: [...e.simplex], value: e.value }));
  return out;
}

// The finest level the slider offers and why it stops there: segments double, triangles
// quadruple, a tetrahedron splits into 4 tetrahedra + 1 octahedron and an octahedron into 8 + 6
// (core/split.c). {max, next}: next is the top-cell count of level max + 1 (null at MAX_LEVEL).
function levelRange(summary) {
  const s = summary?.simplices || {};
  const P = s['0'] || 0;
  let E = s['1'] || 0, T = s['2'] || 0, Tet = s['3'] || 0, O = 0;
  for (let L = 1; L <= MAX_LEVEL; L++) {
    E *= 2;
    T *= 4;
    [Tet, O] = [4 * Tet + 8 * O, Tet + 6 * O];
    const cells = P + E + T + Tet + O;
    if (cells > MAX_CELLS) return { max: Math.max(1, L - 1), next: L > 1 ? cells : null };
  }
  return { max: MAX_LEVEL, next: null };
}

// The summary levelRange reads (top simplices by dimension), from GET /complex.
function summaryOf(complex) {
  const summary = { simplices: {} };
  for (const s of complex.simplices) summary.simplices[s.length - 1] = (summary.simplices[s.length - 1] || 0) + 1;
  return summary;
}

// The address of a session for another tab: a fragment, which never reaches a server (nor its
// logs); the model's name goes with it, so that tab names the model as this one does.
const sessionLink = (id, token, name) =>
  `${location.pathname}#session=${id}&token=${token}${name ? `&name=${encodeURIComponent(name)}` : ''}`;

const millions = (n) => `${(n / 1e6).toPrecision(3)} M`;

function fnv1a(buf) {
  const b = new Uint8Array(buf);
  let h = 0x811c9dc5;
  for (let i = 0; i < b.length; i++) h = Math.imul(h ^ b[i], 0x01000193) >>> 0;
  return h.toString(16).padStart(8, '0');
}

const fmt = (x) => (Number.isInteger(x) ? x.toLocaleString('en') : Number(x).toPrecision(4));

class App {
  constructor() {
    this.viewer = new Viewer($('view'));
    this.session = new Session();
    this.loader = new GLTFLoader();
    this.queue = Promise.resolve();
    this.pending = 0;
    this.model = null; // {name, complex (GET /complex), summary, ranges, bbox, maxLevel}
    this.shown = null; // what the view shows: level, version, stats, GLB size and hash
    this.level = FIRST_LEVEL;
    this.color = { mode: 'rule', attr: null, min: 0, max: 1 };
    this.slice = { on: false, axis: 'z', t: 0.5 };
    this.tool = 'move';
    this.undoStack = [];
    this.redoStack = [];
    this.levelWanted = false;
    this.levelPromise = null;
    this.pendingMoves = new Map(); // "level:index" -> {level, index, position, what, t}
    this.movePromise = null;
    this.editLevel = 0; // the level whose points the move tool drags
    this.handleLevel = null; // {level, version} of a level fetched for its handles (1 ≤ l < shown)
    this.moveFieldsFor = null; // {model, level}: the handles whose point the move fields name
    this.known = 0; // the newest version heard of (answers, events)
    this.cageVersion = 0; // the version the drawn control points are at
    this.complexVersion = 0; // the version of the complex (tags, rules) held
    this.syncPromise = null;
    this.syncWanted = false;
    this.events = null;
    this.perf = { updates: [], deltas: 0, deltaBytes: 0, refetches: 0 };
    this.updating = []; // PATCHes answered whose delta is not drawn yet
    this.updateWaiters = []; // whenUpdates()
    this.patching = false; // a PATCH is under way
    this.heard = 0; // the newest edit event heard while a PATCH was under way
    this.embedding = 0; // our own embedded-model changes under way
    this.ownEmbedded = new Set(); // versions of our own embedded-model changes
    this.selected = null;
    this.messages = [];
    this.ready = false;
  }

  // ---- the request queue ------------------------------------------------------------------

  run(fn) {
    const p = this.queue.then(() => this.#withSession(fn));
    this.queue = p.then(() => {}, () => {}); // the chain goes on; the caller handles p's error
    this.#busy(+1);
    const done = () => this.#busy(-1);
    p.then(done, done);
    return p;
  }

  // "working…" shows when something takes longer than 200 ms (not for every request of a drag:
  // each change of the page costs a layout and a frame)
  #busy(d) {
    this.pending += d;
    if (this.pending === 0) {
      clearTimeout(this.busyTimer);
      this.busyTimer = 0;
      if (!$('busy').hidden) $('busy').hidden = true;
    } else if (!this.busyTimer && $('busy').hidden) {
      this.busyTimer = setTimeout(() => {
        this.busyTimer = 0;
        if (this.pending > 0) $('busy').hidden = false;
      }, 200);
    }
  }

  // A session that expired or was closed elsewhere (404 no-session) is replaced by a new one
  // holding the same model; what was drawn from the old one is fetched again from it.
  async #withSession(fn) {
    try {
      return await fn();
    } catch (e) {
      if (!(e instanceof ApiError && e.status === 404 && e.type.endsWith('no-session') && this.model)) throw e;
      const c = this.model.complex;
      await this.session.open();
      this.session.keep(this.model.name); // a reload of this tab opens the new one, by this name
      await this.session.putComplex({ vertices: c.vertices, simplices: c.simplices, attributes: c.attributes });
      const t = tagsOf(c);
      if (t.singular.length || t.petals || t.sharpness) await this.session.putTags(t, 'Restoring the tags');
      await this.session.putRules(c.rules, 'Restoring the rules');
      let lost = '';
      const emb = this.embedded;
      if (emb?.body) { // this tab's own model: bound again (its rest shape), as after a change of rules
        const put = await this.session.putEmbedded('model', emb.body);
        this.ownEmbedded.add(put.version);
        await this.#fetchEmbedded(emb.file, put.embedded, emb.body);
      } else if (emb) {
        this.#clearEmbedded();
        lost = ` The embedded model ${emb.file} was not kept: embed it again.`;
      }
      // a tab opened by a link now has a session of its own: a reload opens it, not the old one
      if (location.hash) history.replaceState(null, '', location.pathname + location.search);
      await this.#refreshComplex();
      this.#listen();
      this.shown = null; // the new session has no level yet
      this.handleLevel = null;
      this.#updateSession();
      this.info(`The session had expired or was closed elsewhere; a new one was started with the same model.${lost}`);
      const r = await fn();
      this.requestLevel(); // the level drawn was the old session's: fetched from the new one
      return r;
    }
  }

  idle() {
    return this.pending === 0 && !this.levelPromise && !this.movePromise && !this.levelWanted &&
      !this.syncPromise && !this.pendingMoves.size && !this.recutTimer;
  }

  // ---- messages ---------------------------------------------------------------------------

  error(e) {
    const text = e instanceof Error ? e.message : String(e);
    this.#message('error', text);
  }

  info(text) {
    this.#message('info', text);
  }

  #message(kind, text) {
    this.messages.push({ kind, text, at: Date.now() });
    const box = $('messages');
    // the same message again (a drag while the daemon is down fails at every move) counts up
    // on the one shown, moved last, instead of pushing the others out
    let el = [...box.children].find((m) => m.dataset.kind === kind && m.dataset.text === text);
    if (el) {
      el.dataset.count = String(Number(el.dataset.count) + 1);
      el.querySelector('.count').textContent = ` (×${el.dataset.count})`;
      box.append(el);
    } else {
      el = document.createElement('div');
      el.className = `message ${kind}`;
      el.dataset.kind = kind;
      el.dataset.text = text;
      el.dataset.count = '1';
      el.setAttribute('role', kind === 'error' ? 'alert' : 'status');
      const t = document.createElement('span');
      t.className = 'text';
      t.textContent = text;
      const c = document.createElement('span');
      c.className = 'count';
      const x = document.createElement('button');
      x.type = 'button';
      x.title = 'dismiss';
      x.textContent = '×';
      x.onclick = () => el.remove();
      t.append(c);
      el.append(t, x);
      box.append(el);
    }
    while (box.children.length > 4) box.firstChild.remove();
    if (kind === 'info') {
      clearTimeout(el.timer);
      el.timer = setTimeout(() => el.remove(), 6000);
    }
  }

  #hint(text) {
    $('hint').textContent = text;
  }

  // ---- models -----------------------------------------------------------------------------

  async loadModel(name, body, { attribute } = {}) {
    try {
      await this.run(async () => {
        if (!this.session.id) {
          await this.session.open();
          this.#listen();
        }
        if (this.embedded) await this.#dropEmbedded(); // it would be bound to the new complex
        const put = await this.session.putComplex(body);
        const complex = await this.session.getComplex();
        this.#setModel(name, complex, put.summary, attribute);
        this.complexVersion = this.cageVersion = this.known = this.session.version;
      });
    } catch (e) {
      this.error(e);
      return;
    }
    await this.requestLevel();
  }

  #setModel(name, complex, summary, attribute) {
    const ranges = {};
    for (const [a, vals] of Object.entries(complex.attributes || {})) {
      const first = vals.map((v) => (Array.isArray(v) ? v[0] : v)).filter(Number.isFinite);
      ranges[a] = first.length ? [Math.min(...first), Math.max(...first)] : [0, 1];
    }
    const bbox = new THREE.Box3().setFromArray(complex.vertices.flat());
    // the cross-section moves through the solids (all of the model when it has none)
    const inSolids = complex.simplices.filter((s) => s.length === 4).flat();
    const solidBox = inSolids.length ? new THREE.Box3().setFromPoints(inSolids.map((i) => new THREE.Vector3(...complex.vertices[i]))) : bbox;
    const range = levelRange(summary);
    this.model = { name, complex, summary, ranges, bbox, solidBox, maxLevel: range.max };
    this.session.keep(name); // a reload of this tab opens it again, by this name
    this.undoStack = [];
    this.redoStack = [];
    this.selected = null;
    this.angleTagged = null;
    $('crease-angle-on').checked = false;
    $('override').hidden = true;
    this.level = Math.min(this.level, this.model.maxLevel);
    $('level').max = this.model.maxLevel;
    $('level').value = this.level;
    $('level-value').textContent = this.level;
    this.#levelNote(range.next === null
      ? `The slider stops at level ${range.max}, the deepest the page offers.`
      : `The slider stops at level ${range.max}: level ${range.max + 1} would have ${millions(range.next)} cells, over the page's limit of ${millions(MAX_CELLS)}.`);
    $('model-name').textContent = `${name}: ${complex.vertices.length} vertices, ${complex.simplices.length} simplices`;
    this.#syncModelSelect(name);
    // colour choices: rule families, each attribute, plain
    const sel = $('color-mode');
    sel.replaceChildren(new Option('rule family', 'rule'));
    for (const a of Object.keys(ranges)) sel.append(new Option(`attribute: ${a}`, `attr:${a}`));
    sel.append(new Option('sharpness (control cage)', 'sharpness'));
    sel.append(new Option('plain', 'plain'));
    if (this.color.mode === 'attribute' && !(this.color.attr in ranges)) this.color.mode = 'rule';
    if (attribute && attribute in ranges && this.color.mode === 'attribute') this.#setColorAttr(attribute);
    sel.value = this.color.mode === 'attribute' ? `attr:${this.color.attr}` : this.color.mode;
    this.viewer.setCage(complex);
    this.viewer.frame(bbox);
    this.#sliceToViewer();
    this.#syncRuleControls();
    this.#syncUndo();
    this.#tagsNote();
    this.#updateSession(); // the link names the new model
  }

  // The model selector shows what is loaded: the example of that name, else the file's name
  // (an extra option, "file: NAME").
  #syncModelSelect(name) {
    const sel = $('example');
    const ex = EXAMPLES.find((e) => e.name === name);
    let opt = [...sel.options].find((o) => o.value === 'file');
    if (ex) {
      opt?.remove();
      sel.value = ex.id;
      return;
    }
    if (!opt) sel.append(opt = new Option('', 'file'));
    opt.textContent = `file: ${name}`;
    sel.value = 'file';
  }

  // The daemon refused a level by one of its limits (413 with `limit`: max_cells, its cell
  // count estimate, or max_session_bytes): the slider stops below it and says why.
  #levelRefused(e) {
    if (!(e instanceof ApiError && e.status === 413 && e.problem.limit !== undefined && this.model)) return false;
    const L = this.level;
    if (L < 1) return false;
    this.model.maxLevel = Math.min(this.model.maxLevel, L - 1);
    this.level = Math.min(this.shown?.level ?? L - 1, this.model.maxLevel);
    $('level').max = this.model.maxLevel;
    $('level').value = this.level;
    $('level-value').textContent = this.level;
    const what = e.problem.limit_name || e.problem.name || 'its limit';
    this.#levelNote(`The slider stops at level ${this.model.maxLevel}: the daemon refuses level ${L} (${what}: ${e.problem.detail || e.message}).`);
    return true;
  }

  // A level that could not be fetched (the daemon unreachable, busy, …; the message says): the
  // slider goes back to the level drawn, so that it does not claim one that is not shown.
  #levelBack() {
    if (!this.shown || this.level === this.shown.level) return;
    this.level = this.shown.level;
    $('level').value = this.level;
    $('level-value').textContent = this.level;
  }

  // Why the level slider stops where it does (under the slider).
  #levelNote(text) {
    $('level-note').textContent = text;
  }

  async #refreshComplex() {
    const complex = await this.session.getComplex();
    this.model.complex = complex;
    this.complexVersion = this.cageVersion = this.session.version;
    this.known = Math.max(this.known, this.session.version);
    this.viewer.setCage(complex);
    this.#syncRuleControls();
    this.#tagsNote();
    if (this.selected) this.#showOverride(this.selected);
  }

  // The session's complex was replaced elsewhere: the page takes it as a model of its own, as
  // join() does (a refined model keeps its name; a new one is named by the session).
  async #takeComplex(kind) {
    const complex = await this.session.getComplex();
    const name = kind === 'refine' ? this.model.name : `session ${this.session.id.slice(0, 8)}`;
    this.#setModel(name, complex, summaryOf(complex));
    this.complexVersion = this.cageVersion = this.session.version;
    this.known = Math.max(this.known, this.session.version);
    this.handleLevel = null;
    this.info(kind === 'refine' ? 'The model was refined in another tab; its new control points are shown.'
      : 'Another tab loaded a new model into this session; it is shown here.');
  }

  async resync() {
    try {
      await this.run(() => this.#refreshComplex());
    } catch (e) {
      this.error(e);
    }
    this.requestLevel();
  }

  // ---- an embedded model (free-form deformation, docs/WEB.md) -------------------------------

  // Bind a mesh file's triangles (or points) to the shown level; it then follows every drag.
  async embedFile(file) {
    if (!this.model) return this.info('Load a model with solids first.');
    let body;
    try {
      const binary = BINARY_TYPES.includes(file.name.toLowerCase().split('.').pop());
      body = parseMeshFile(file.name, binary ? await file.arrayBuffer() : await file.text());
    } catch (e) {
      this.error(`Reading ${file.name} failed: ${e.message}`);
      return;
    }
    const triangles = body.simplices.filter((t) => t.length === 3);
    const level = this.level;
    try {
      await this.run(async () => {
        // "nearest": subdivision shrinks the solid, so a model near the cage's boundary binds too
        this.embedding++;
        let put;
        try {
          put = await this.session.putEmbedded('model', { vertices: body.vertices, triangles, level, outside: 'nearest' });
          this.ownEmbedded.add(put.version);
        } finally {
          this.embedding--;
        }
        this.known = Math.max(this.known, put.version);
        if (this.cageVersion === put.version - 1) this.cageVersion = put.version; // points as they were
        if (this.complexVersion === put.version - 1) this.complexVersion = put.version;
        await this.#fetchEmbedded(file.name, put.embedded, { vertices: body.vertices, triangles, level, outside: 'nearest' });
        this.requestSync();
      });
    } catch (e) {
      this.error(e);
    }
  }

  // body: what was put (this tab's own model; a session that is gone is given it again)
  async #fetchEmbedded(name = this.embedded?.file, summary = this.embedded?.summary, body = this.embedded?.body) {
    const j = await this.session.getEmbedded('model');
    this.viewer.setEmbedded(new Float32Array(j.vertices.flat()), new Uint32Array(j.triangles.flat()));
    this.embedded = { file: name, summary, body, version: j.version, level: j.level, busy: false, again: false, deltas: 0 };
    this.session.keepEmbedded(name); // a reload of this tab names it again
    const out = summary?.outside_vertices ? `, ${summary.outside_vertices} bound to the nearest cell` : '';
    $('embed-note').textContent = `${name}: ${j.vertices.length} vertices bound to level ${j.level}${out}; it follows the solid.`;
    $('embed-remove').disabled = false;
  }

  async #dropEmbedded() {
    const before = this.session.version;
    this.embedding++;
    try {
      await this.session.deleteEmbedded('model');
      this.ownEmbedded.add(this.session.version);
    } finally {
      this.embedding--;
    }
    if (this.cageVersion === before) this.cageVersion = this.session.version;
    if (this.complexVersion === before) this.complexVersion = this.session.version;
    this.#clearEmbedded();
  }

  // No embedded model drawn (it is not in the session).
  #clearEmbedded() {
    this.embedded = null;
    this.viewer.setEmbedded(null);
    $('embed-note').textContent = '';
    $('embed-remove').disabled = true;
    this.session.keepEmbedded(null);
  }

  // The session's embedded model as it is now (GET /embedded): drawn, or taken away when there
  // is none — a tab that opened the session (a reload, the link) or heard another tab change it.
  async #loadEmbedded(name = this.embedded?.file) {
    const list = await this.session.listEmbedded();
    const it = (list.embedded || []).find((m) => m.name === 'model');
    if (!it) {
      if (this.embedded) this.#clearEmbedded();
      return;
    }
    try {
      await this.#fetchEmbedded(name || 'model', it, this.embedded?.body);
    } catch (e) {
      if (!(e instanceof ApiError && e.status === 404 && !e.type.endsWith('no-session'))) throw e;
      this.#clearEmbedded(); // removed meanwhile
    }
  }

  removeEmbedded() {
    if (!this.embedded) return;
    this.run(() => this.#dropEmbedded()).catch((e) => this.error(e));
  }

  // After the shown level moved: the embedded model's vertices that moved too (one request in
  // flight; a 410 — the model was bound again after a change — fetches it whole).
  #followEmbedded() {
    const e = this.embedded;
    if (!e) return;
    if (e.busy) {
      e.again = true;
      return;
    }
    e.busy = true;
    (async () => {
      try {
        do {
          e.again = false;
          if (e.version >= this.session.version) break;
          const d = await this.session.embeddedDelta('model', e.version);
          if (this.embedded !== e) return;
          this.viewer.moveEmbedded(d);
          e.version = d.version;
          e.deltas++;
        } while (e.again);
      } catch (err) {
        if (err instanceof ApiError && (err.status === 410 || err.status === 404)) {
          if (this.embedded === e) await this.#fetchEmbedded().catch(() => {});
        } else this.error(err);
      } finally {
        e.busy = false;
      }
    })();
  }

  async openFile(file) {
    let body;
    try {
      const binary = BINARY_TYPES.includes(file.name.toLowerCase().split('.').pop());
      body = parseMeshFile(file.name, binary ? await file.arrayBuffer() : await file.text());
    } catch (e) {
      this.error(`Reading ${file.name} failed: ${e.message}`);
      return;
    }
    await this.loadModel(file.name, body);
  }

  // ---- levels -----------------------------------------------------------------------------

  levelQuery() {
    const q = {};
    if (this.slice.on) {
      const { n, d } = this.#slicePlane();
      q.slice = [...n, d].map((x) => +x.toPrecision(9)).join(',');
    }
    if (this.color.mode === 'attribute') q.colormap = `${this.color.attr}:${this.color.min}:${this.color.max}`;
    return q;
  }

  // Fetch the wanted level (coalescing): resolves once the view shows the latest wish.
  requestLevel() {
    this.levelWanted = true;
    if (this.levelPromise) return this.levelPromise;
    this.levelPromise = (async () => {
      try {
        while (this.levelWanted && this.model) {
          this.levelWanted = false;
          await this.run(() => this.#fetchLevel());
        }
      } catch (e) {
        this.levelWanted = false;
        this.error(e);
        if (!this.#levelRefused(e)) this.#levelBack();
      } finally {
        this.levelPromise = null;
      }
    })();
    return this.levelPromise;
  }

  async #fetchLevel() {
    const L = this.level, query = this.levelQuery();
    const t0 = performance.now();
    const stats = await this.session.stats(L);
    const buf = await this.session.levelGlb(L, query);
    const version = this.session.version; // the GLB's ETag: the version of its content
    const gltf = await this.loader.parseAsync(buf, '');
    this.viewer.setLevel(gltf, stats);
    this.known = Math.max(this.known, version);
    this.shown = {
      level: L, version, cut: version, query, stats, bytes: buf.byteLength,
      hash: fnv1a(buf), ms: performance.now() - t0, parts: Object.keys(this.viewer.parts),
      rules: this.#levelRuleCounts(), deltas: 0, fetches: (this.shown?.fetches ?? 0) + 1,
    };
    this.perf.refetches++;
    this.#updatesDone(null);
    this.#syncEditLevels();
    if (this.embedded && this.embedded.version < version) await this.#fetchEmbedded(); // bound anew
    await this.#setupHandles();
    this.#showStats();
    this.#legend();
    this.#updateSession();
    if (this.tool === 'move') this.#hint(`Level ${L} of “${this.model.name}”. ${TOOL_HINTS.move}.`);
  }

  // How many vertices of the shown level follow each rule family (the GLB's `_RULE`, one
  // accessor shared by the primitives).
  #levelRuleCounts() {
    const counts = {};
    const o = Object.values(this.viewer.parts).find((p) => (p.userData.source || p.geometry).attributes._rule);
    const r = o && (o.userData.source || o.geometry).attributes._rule;
    for (let i = 0; r && i < r.count; i++) {
      const fam = ruleFamily(RULE_NAMES[Math.round(r.getX(i))] ?? 'unknown');
      counts[fam] = (counts[fam] || 0) + 1;
    }
    return counts;
  }

  #showStats() {
    const s = this.shown.stats, c = s.counts || {};
    const rows = [
      ['level', s.level], ['fetched at version', s.version ?? this.shown.version],
      ['vertices', c.vertices], ['edges', c.edges], ['faces', c.faces],
      ['points', c.points], ['curve segments', c.curves], ['surface triangles', c.triangles],
      ['tetrahedra', c.tetrahedra], ['octahedra', c.octahedra],
      ['compute (s)', s.seconds], ['memory (bytes)', s.memory_bytes],
      ['GLB (bytes)', this.shown.bytes], ['fetch (ms)', Math.round(this.shown.ms)],
    ];
    const dl = document.createElement('dl');
    dl.className = 'stats';
    for (const [k, v] of rows) {
      if (v === undefined) continue;
      const dt = document.createElement('dt');
      dt.textContent = k;
      const dd = document.createElement('dd');
      dd.textContent = fmt(v);
      dd.dataset.stat = k;
      dl.append(dt, dd);
    }
    $('stats').replaceChildren(dl);
    const cells = ['points', 'curves', 'triangles', 'tetrahedra', 'octahedra']
      .reduce((n, k) => n + (c[k] || 0), 0);
    this.viewer.canvas.setAttribute('aria-label', `3D view: ${this.model?.name ?? 'model'}, level ` +
      `${s.level}, ${fmt(c.vertices ?? 0)} vertices, ${fmt(cells)} cells; drag to orbit, ` +
      `arrow keys to pan, wheel to zoom`);
  }

  // At most 4 times a second (a drag changes the version at every update).
  #updateSession() {
    if (this.sessionTimer) return;
    this.sessionTimer = setTimeout(() => {
      this.sessionTimer = 0;
      this.#showSession();
    }, 250);
  }

  #showSession() {
    const s = this.session;
    $('session').textContent = s.id ? `session ${s.id.slice(0, 8)} · v${s.version}` : 'no session';
    $('share').href = s.id ? sessionLink(s.id, s.token, this.model?.name) : '#';
  }

  // Open a session another tab started (/#session=ID&token=TOKEN): its model, then follow it.
  // With `owned`, the session this tab started before a reload (Session.kept()): its TTL is set
  // back from the short one the page gave it as it went, and a session gone meanwhile is said
  // as such, not as an error.
  async join(id, token, { owned = false, name, embedded } = {}) {
    try {
      await this.run(async () => {
        this.session.id = id;
        this.session.token = token;
        this.session.version = 0;
        this.session.owned = owned;
        if (owned) {
          await this.session.setTtl(TTL_S);
          this.session.markLive();
          // the page that went sent its short TTL with keepalive: should it arrive after ours,
          // ours again once it has surely arrived
          setTimeout(() => {
            if (this.session.owned && this.session.id === id) this.session.setTtl(TTL_S).catch((e) => this.error(e));
          }, 3000);
        }
        const complex = await this.session.getComplex();
        this.#setModel(name || `session ${id.slice(0, 8)}`, complex, summaryOf(complex));
        this.complexVersion = this.cageVersion = this.known = this.session.version;
        await this.#loadEmbedded(embedded); // drawn as the tab that embedded it drew it
        this.#listen();
      });
    } catch (e) {
      this.session.id = this.session.token = null;
      this.session.owned = false;
      if (e instanceof ApiError && [401, 404, 409].includes(e.status) && (owned || e.status !== 409)) {
        if (owned) Session.forget();
        else history.replaceState(null, '', location.pathname + location.search); // a reload starts afresh
        this.info(`The session of ${owned ? 'this tab' : 'the link'} is gone (${e.status === 409 ? 'it held no model' : 'it expired or was closed'}); starting again.`);
      } else this.error(e);
      return false;
    }
    await this.requestLevel();
    return true;
  }

  // ---- the live loop: handles, deltas, events -----------------------------------------------

  // The edit-level choice offers 0 … the shown level.
  #syncEditLevels() {
    const sel = $('edit-level'), top = this.shown?.level ?? 0;
    if (this.editLevel > top) this.editLevel = 0;
    if (sel.options.length !== top + 1) {
      sel.replaceChildren(...Array.from({ length: top + 1 }, (_, l) =>
        new Option(l === 0 ? '0 (control points)' : `${l}`, l)));
    }
    sel.value = this.editLevel;
  }

  async setEditLevel(l) {
    this.editLevel = l;
    try {
      await this.run(() => this.#setupHandles());
    } catch (e) {
      this.error(e);
    }
    this.#hint(this.#moveHint());
  }

  #moveHint() {
    const l = this.editLevel;
    return l === 0 ? `${TOOL_HINTS.move}.` :
      `Drag a point of level ${l}: it stores a detail offset there (coarser edits keep it).`;
  }

  // The handles of the edit level: the cage, the shown level's own vertices, or a level fetched
  // for them (kept up to date by its own deltas).
  async #setupHandles() {
    const l = this.editLevel, v = this.viewer;
    if (l === 0 || !this.shown) {
      this.handleLevel = null;
      v.setHandles(0);
    } else if (l === this.shown.level) {
      this.handleLevel = null;
      v.setHandles(l, v.levelPositions(), Viewer.interiorOf(v.level.count, v.level.prims));
    } else {
      const buf = await this.session.levelGlb(l, {});
      const version = this.session.version;
      const gltf = await this.loader.parseAsync(buf, '');
      const prims = [];
      gltf.scene.traverse((o) => { if (o.isMesh || o.isPoints || o.isLine) prims.push(o); });
      const attr = prims.find((o) => o.geometry.index || o.geometry.attributes._rule)?.geometry.attributes.position;
      if (!attr) throw new Error(`level ${l} has no points to drag`);
      this.handleLevel = { level: l, version, attr };
      v.setHandles(l, attr, Viewer.interiorOf(attr.count, prims));
      this.#updateSession();
    }
    this.#syncMoveFields();
  }

  // Bring what is drawn up to the newest version heard of, by deltas: the shown level, the
  // handle level and (for changes made elsewhere) the control points. 410: fetch again (here
  // when called from a request of the queue, else as a request of the queue).
  async #syncNow(inQueue = false, force = false) {
    if (!this.shown || !this.model) return;
    let want = Math.max(this.known, this.session.version);
    if (this.shown.version < want || force) {
      const L = this.shown.level, since = this.shown.version;
      const d = await this.#deltaOr410(() => this.session.delta(L, since));
      if (!d && !inQueue) {
        this.requestLevel();
        return;
      }
      if (!d) {
        await this.#fetchLevel(); // also sets the handles up again
        return this.#syncCage(Math.max(want, this.shown.version), true);
      }
      want = Math.max(want, d.version);
      if (d.level !== L || d.since !== since) throw new Error(`delta of level ${d.level} since ${d.since}, asked ${L} since ${since}`);
      if (this.shown.level !== L || this.shown.version !== since) {
        // a PATCH's own delta (#patch) was drawn meanwhile: this one is stale; ask again
        if (this.shown.level === L && this.shown.version < want) this.syncWanted = true;
        return;
      }
      try {
        this.#applyShownDelta(d);
      } catch (e) {
        this.info(`The level is fetched again (${e.message}).`);
        if (!inQueue) return this.requestLevel();
        await this.#fetchLevel();
        return this.#syncCage(want, true);
      }
    }
    this.#updatesDone(null);
    const h = this.handleLevel;
    if (h && h.version < want) {
      const d = await this.#deltaOr410(() => this.session.delta(h.level, h.version));
      if (!d) await (inQueue ? this.#setupHandles() : this.run(() => this.#setupHandles()));
      else {
        const a = h.attr.array;
        for (let k = 0; k < d.n; k++) a.set(d.positions.subarray(3 * k, 3 * k + 3), 3 * d.indices[k]);
        h.attr.needsUpdate = true;
        h.version = d.version;
        this.viewer.requestRender();
      }
    }
    await this.#syncCage(want, inQueue);
    this.#updateSession();
  }

  // A delta of the shown level, since the version its buffers hold, written into them.
  #applyShownDelta(d) {
    this.viewer.applyDelta(d);
    this.#followEmbedded();
    this.shown.version = d.version;
    this.#recutSoon();
    this.shown.deltas++;
    this.perf.deltas++;
    this.perf.deltaBytes += d.bytes;
    this.#updatesDone(d);
  }

  // The slice primitive is not part of a delta: with the cut on, a level that deltas moved is
  // fetched again once they pause — after an undo or redo, another tab's edits (a drag of this
  // tab fetches it as the drag ends, onPointerUp).
  #recutSoon() {
    if (!this.slice.on) return;
    clearTimeout(this.recutTimer);
    this.recutTimer = setTimeout(() => {
      this.recutTimer = 0;
      if (!this.slice.on || !this.shown) return;
      if (this.drag || this.levelPromise || this.movePromise || this.syncPromise) return this.#recutSoon();
      if (this.shown.version > this.shown.cut) this.requestLevel();
    }, 250);
  }

  // The control points changed elsewhere: a JSON delta of level 0 (exact doubles).
  async #syncCage(want, inQueue = false) {
    if (this.cageVersion >= want) return;
    const since = this.cageVersion;
    let d = null;
    try {
      const res = await this.session.request('Updating the control points', 'GET', '/levels/0/delta', { query: { since, format: 'json' } });
      d = await res.json();
    } catch (e) {
      if (!(e instanceof ApiError && e.status === 410)) throw e;
    }
    if (!d) {
      await (inQueue ? this.#refreshComplex() : this.run(() => this.#refreshComplex()));
      return;
    }
    const verts = this.model.complex.vertices;
    d.indices.forEach((i, k) => { verts[i] = d.positions[k].slice(); });
    if (d.indices.length) this.viewer.moveCageVertices(d.indices, d.positions.flat());
    this.cageVersion = d.version;
  }

  async #deltaOr410(get) {
    try {
      return await get();
    } catch (e) {
      if (e instanceof ApiError && e.status === 410) return null;
      throw e;
    }
  }

  // Coalesced: one sync at a time, and one more if asked meanwhile. Deltas are reads: they do
  // not wait in the request queue, so the next PATCH of a drag is under way meanwhile.
  requestSync() {
    this.syncWanted = true;
    if (this.syncPromise) return this.syncPromise;
    this.syncPromise = (async () => {
      try {
        while (this.syncWanted) {
          this.syncWanted = false;
          await this.#withSession(() => this.#syncNow());
        }
      } catch (e) {
        this.error(e);
      } finally {
        this.syncPromise = null;
      }
    })();
    return this.syncPromise;
  }

  // The session's events: another tab's edits are followed by deltas, its other changes by
  // fetching the complex and the level again.
  #listen() {
    this.events?.close();
    const id = this.session.id;
    if (typeof EventSource === 'undefined' || !id) return;
    this.events = this.session.events({
      version: (data, v) => {
        if (this.session.id !== id || !this.model || !Number.isFinite(v)) return;
        if (data.kind === 'embedded') { // the control complex is as it was: the level stays
          this.known = Math.max(this.known, v);
          if (this.complexVersion === v - 1) this.complexVersion = v;
          if (this.cageVersion === v - 1) this.cageVersion = v;
          // ours (under way, or answered): the drawn level is that version's, nothing to fetch
          // (a delta asked now could meet the change that follows, a new complex: 410)
          if (this.embedding || this.ownEmbedded.delete(v)) {
            if (this.shown && this.shown.version === v - 1) this.shown.version = v;
            return;
          }
          if (this.shown && this.shown.version < v) this.requestSync();
          // another tab embedded, replaced or removed the model: drawn as the session has it
          this.run(() => this.#loadEmbedded()).catch((e) => this.error(e));
          return;
        }
        if (data.kind === 'edit') {
          // an edit heard while our PATCH is under way is most likely that PATCH: its answer
          // says (and syncs); otherwise it was made elsewhere
          if (this.patching) {
            this.heard = Math.max(this.heard, v);
            return;
          }
          this.known = Math.max(this.known, v);
          if (this.shown && this.shown.version < v) this.requestSync();
          return;
        }
        this.known = Math.max(this.known, v);
        this.run(async () => {
          if (this.complexVersion >= v) return; // ours, or already fetched
          // a new complex (another tab loaded a model, or refined it): its points are numbered
          // anew, so it is taken as a model of its own (attributes, levels offered, undo)
          if (data.kind === 'complex' || data.kind === 'refine') await this.#takeComplex(data.kind);
          else await this.#refreshComplex();
          this.requestLevel();
        }).catch((e) => this.error(e));
      },
      resync: () => this.resync(),
      // an answer other than the stream (404: the session went without a `deleted` event, as
      // in a restart of a daemon without a durable store; 429: too many listeners) closes an
      // EventSource for good (a daemon out of reach is retried by the browser): the complex is
      // read again — a gone session is replaced by a new one, which is listened to, and said —
      // and a tab that no longer hears the changes says so
      error: (ev, es) => {
        if (es.readyState !== 2 || this.events !== es || this.session.id !== id) return;
        this.resync().then(() => {
          if (this.events === es && this.session.id === id)
            this.error('This tab no longer follows the changes made elsewhere (the daemon refused its event stream); reload the page to follow them again.');
        });
      },
      deleted: (data) => {
        if (this.session.id !== id) return;
        this.events?.close();
        const why = data?.reason === 'expired' ? 'expired' : data?.reason === 'evicted' ? 'was evicted'
          : 'was closed by another client';
        this.info(`The session ${why}; the next change starts a new one with the same model.`);
      },
    });
  }

  // ---- colour -----------------------------------------------------------------------------

  #setColorAttr(a) {
    this.color.mode = 'attribute';
    this.color.attr = a;
    let [lo, hi] = this.model.ranges[a];
    if (!(hi > lo)) hi = lo + 1;
    this.color.min = +lo.toPrecision(6);
    this.color.max = +hi.toPrecision(6);
    $('color-min').value = this.color.min;
    $('color-max').value = this.color.max;
  }

  setColorMode(value) {
    if (value.startsWith('attr:')) this.#setColorAttr(value.slice(5));
    else this.color.mode = value;
    $('range').hidden = this.color.mode !== 'attribute';
    this.viewer.setColorMode(this.color.mode);
    this.#legend();
    this.requestLevel(); // COLOR_0 comes with colormap=
  }

  #legend() {
    const box = $('legend');
    box.replaceChildren();
    if (this.color.mode === 'attribute') {
      const title = document.createElement('div');
      title.textContent = `${this.color.attr} (first component, viridis)`;
      const bar = document.createElement('div');
      bar.className = 'bar';
      bar.style.background = viridisCss();
      const labels = document.createElement('div');
      labels.className = 'bar-labels';
      const mid = (this.color.min + this.color.max) / 2;
      for (const v of [this.color.min, mid, this.color.max]) {
        const s = document.createElement('span');
        s.textContent = +v.toPrecision(4);
        labels.append(s);
      }
      box.append(title, bar, labels);
      return;
    }
    if (this.color.mode === 'sharpness') {
      const title = document.createElement('div');
      title.textContent = 'control edges and vertices by sharpness';
      const bar = document.createElement('div');
      bar.className = 'bar';
      bar.style.background = sharpnessCss();
      const labels = document.createElement('div');
      labels.className = 'bar-labels';
      for (const v of ['0', '5', '≥ 10 (singular)']) {
        const s = document.createElement('span');
        s.textContent = v;
        labels.append(s);
      }
      box.append(title, bar, labels);
      return;
    }
    if (this.color.mode !== 'rule' || !this.model) return;
    // the families present: the cage's vertices and edges, and the shown level's vertices
    const seen = new Set();
    for (const c of this.model.complex.classes.vertices) seen.add(ruleFamily(c.rule));
    for (const c of this.model.complex.classes.edges) seen.add(ruleFamily(c.rule));
    for (const o of Object.values(this.viewer.parts)) {
      const r = (o.userData.source || o.geometry).attributes._rule;
      if (r) for (let i = 0; i < r.count; i++) seen.add(ruleFamily(RULE_NAMES[Math.round(r.getX(i))] ?? 'unknown'));
    }
    const order = [...RULE_NAMES, 'ying-zorin', 'unknown'];
    for (const fam of order.filter((f) => seen.has(f))) {
      const row = document.createElement('div');
      row.className = 'legend-row';
      row.dataset.rule = fam;
      const sw = document.createElement('span');
      sw.className = 'swatch';
      sw.style.background = ruleHex(fam);
      const name = document.createElement('span');
      name.className = 'name';
      name.textContent = fam;
      const desc = document.createElement('span');
      desc.className = 'desc';
      desc.textContent = RULE_DESCRIPTIONS[fam] || '';
      row.append(sw, name, desc);
      box.append(row);
    }
  }

  // ---- cross-section ----------------------------------------------------------------------

  #slicePlane() {
    const axis = { x: 0, y: 1, z: 2 }[this.slice.axis];
    const n = [0, 0, 0];
    n[axis] = 1;
    const lo = this.model.solidBox.min.getComponent(axis), hi = this.model.solidBox.max.getComponent(axis);
    return { n, d: lo + this.slice.t * (hi - lo) };
  }

  #sliceToViewer() {
    if (this.slice.on && this.model) {
      const { n, d } = this.#slicePlane();
      this.viewer.setSlice(n, d);
    } else this.viewer.setSlice(null);
  }

  setSlice(change) {
    Object.assign(this.slice, change);
    this.#sliceToViewer();
    this.requestLevel();
  }

  // ---- moving control points ----------------------------------------------------------------

  // Ask the daemon to move point `index` of level `level` (coalescing: while a PATCH is under
  // way, later moves wait, the latest position of each point wins, and all that waited go in
  // one PATCH), then bring the drawn level up to date by a delta.
  queueMove(level, index, position, what = 'Moving a control point', t = performance.now()) {
    const k = `${level}:${index}`;
    const prev = this.pendingMoves.get(k);
    this.pendingMoves.delete(k); // re-inserted last: moves keep the order they were last made in
    this.pendingMoves.set(k, { level, index, position: position.toArray ? position.toArray() : position, what, t: prev ? prev.t : t, last: t });
    if (this.movePromise) return this.movePromise;
    this.movePromise = (async () => {
      try {
        while (this.pendingMoves.size) {
          const moves = [...this.pendingMoves.values()];
          this.pendingMoves.clear();
          await this.run(() => this.#patch(moves));
        }
      } catch (e) {
        this.pendingMoves.clear();
        this.error(e);
        this.resync(); // show the daemon's positions again
      } finally {
        this.movePromise = null;
      }
    })();
    return this.movePromise;
  }

  async #patch(moves) {
    const body = moves.map((m) => (m.level ? { index: m.index, level: m.level, position: m.position } : { index: m.index, position: m.position }));
    const what = moves.length === 1 ? moves[0].what : `Moving ${moves.length} points`;
    const t0 = performance.now();
    let r;
    // the shown level up to date and no delta under way: the PATCH answers with its delta of the
    // shown level (one round trip); otherwise the delta follows (requestSync)
    const direct = this.shown && !this.syncPromise && this.shown.version === this.session.version;
    this.patching = true;
    try {
      try {
        r = direct ? await this.session.moveControlPointsDelta(body, this.shown.level, what)
          : await this.session.moveControlPoints(body, what);
      } catch (e) {
        // 412: the session changed elsewhere; catch up and send the move again (once)
        if (!(e instanceof ApiError && e.status === 412)) throw e;
        await this.syncPromise; // a delta under way first
        await this.#syncNow(true, true); // a delta (or a refetch) tells the version
        r = await this.session.moveControlPoints(body, what);
      }
    } finally {
      this.patching = false;
    }
    const t1 = performance.now();
    const cageWasCurrent = this.cageVersion + 1 === r.version;
    for (const m of moves) if (m.level === 0) this.model.complex.vertices[m.index] = m.position;
    if (cageWasCurrent) this.cageVersion = r.version; // nothing but this PATCH since
    this.known = Math.max(this.known, r.version, this.heard);
    // the delta goes its own way (requestSync), so the next PATCH can start meanwhile; the
    // update is complete when the buffers hold r.version
    this.updating.push({
      move: Math.min(...moves.map((m) => m.t)), lastMove: Math.max(...moves.map((m) => m.last)),
      sent: t0, patched: t1, version: r.version, moves: moves.length,
    });
    const d = r.delta;
    if (d && this.shown && d.level === this.shown.level && d.since === this.shown.version) {
      try {
        this.#applyShownDelta(d);
      } catch (e) {
        this.info(`The level is fetched again (${e.message}).`);
        return this.requestLevel();
      }
      this.#updateSession();
      // what the answer did not bring: the handle level's points, changes made elsewhere
      if (this.handleLevel || this.known > this.shown.version || this.cageVersion < this.known) this.requestSync();
      return;
    }
    this.requestSync();
  }

  // Updates (PATCHes) whose versions the shown level now holds are done: timings for benchmarks.
  #updatesDone(d) {
    const t = performance.now(), u = this.perf.updates;
    while (this.updating.length && this.updating[0].version <= this.shown.version) {
      const x = this.updating.shift();
      u.push({ ...x, applied: t, points: d?.n ?? 0, bytes: d?.bytes ?? 0, delta: d?.since ?? null });
    }
    if (u.length > 20000) u.splice(0, u.length - 10000);
    if (this.updateWaiters.length) {
      const ready = this.updateWaiters.filter((w) => w.n <= u.length);
      this.updateWaiters = this.updateWaiters.filter((w) => w.n > u.length);
      ready.forEach((w) => w.resolve());
    }
  }

  // For benchmarks and tests: resolves once perf.updates holds n entries (no polling).
  whenUpdates(n) {
    if (this.perf.updates.length >= n) return Promise.resolve();
    return new Promise((resolve) => this.updateWaiters.push({ n, resolve }));
  }

  #move(entry, to, what) {
    const p = new THREE.Vector3(...to);
    if (entry.level === 0) this.viewer.moveCageVertex(entry.index, p);
    else if (this.viewer.handles?.level === entry.level) this.viewer.moveHandle(entry.index, p);
    this.queueMove(entry.level, entry.index, p, what);
  }

  // ---- moving a point by keyboard: its number and new coordinates typed -------------------

  // The point of the edit level's handles: its position now (level 0: the control point as the
  // daemon has it; finer: the drawn float32 point), or null.
  #handlePoint(i) {
    const h = this.viewer.handles;
    if (!h || !Number.isInteger(i) || i < 0 || i >= h.count) return null;
    return h.level === 0 ? this.model.complex.vertices[i].slice() : this.viewer.handlePosition(i).toArray();
  }

  // Fill the fields with point i (picked, dragged or typed) and where it is.
  #fillMoveFields(i, at = this.#handlePoint(i)) {
    $('move-index').value = i;
    this.#moveFieldsNow();
    if (!at) return;
    ['move-x', 'move-y', 'move-z'].forEach((id, k) => { $(id).value = at[k]; });
  }

  // The fields hold a point of these handles (a model and a level) from now on.
  #moveFieldsNow() {
    this.moveFieldsFor = { model: this.model, level: this.viewer.handles?.level ?? 0 };
  }

  // The handles changed (another edit level, a new model): the number now names another point,
  // so its coordinates are that point's (emptied when there is no such point), not the ones
  // filled or typed for the point it named before. true when the fields changed.
  #syncMoveFields() {
    const f = this.moveFieldsFor, h = this.viewer.handles;
    if (!f || (f.model === this.model && f.level === (h?.level ?? 0))) return false;
    const raw = $('move-index').value, i = raw === '' ? NaN : Number(raw), at = this.#handlePoint(i);
    if (at) this.#fillMoveFields(i, at);
    else {
      ['move-x', 'move-y', 'move-z'].forEach((id) => { $(id).value = ''; });
      this.#moveFieldsNow();
    }
    return true;
  }

  moveExact() {
    const h = this.viewer.handles, level = h?.level ?? 0;
    if (h && level !== this.editLevel) { // the edit level's points are still being fetched
      this.info(`The points of level ${this.editLevel} are still loading: nothing was moved.`);
      return;
    }
    if (this.#syncMoveFields()) {
      this.info(`The fields now show point ${$('move-index').value} of level ${level} where it is: nothing was moved.`);
      return;
    }
    const i = Number($('move-index').value);
    const from = this.#handlePoint(i);
    if ($('move-index').value === '' || !from) {
      this.info(h ? `No point ${$('move-index').value} of level ${level}: the points are numbered 0 to ${h.count - 1}.` : 'No points to move yet.');
      return;
    }
    const to = ['move-x', 'move-y', 'move-z'].map((id) => $(id).value.trim() === '' ? NaN : Number($(id).value));
    if (!to.every(Number.isFinite)) {
      this.info('Type the new x, y and z of the point as numbers.');
      return;
    }
    if (to.every((x, k) => x === from[k])) return;
    this.undoStack.push({ level, index: i, from, to });
    this.redoStack = [];
    this.#syncUndo();
    this.#move({ level, index: i }, to, level ? `Moving point ${i} of level ${level}` : `Moving control point ${i}`);
    if (this.slice.on) this.requestLevel(); // the slice is not part of a delta
  }

  undo() {
    const e = this.undoStack.pop();
    if (!e) return;
    this.redoStack.push(e);
    this.#move(e, e.from, `Undoing the move of point ${e.index}${e.level ? ` of level ${e.level}` : ''}`);
    this.#syncUndo();
  }

  redo() {
    const e = this.redoStack.pop();
    if (!e) return;
    this.undoStack.push(e);
    this.#move(e, e.to, `Redoing the move of point ${e.index}${e.level ? ` of level ${e.level}` : ''}`);
    this.#syncUndo();
  }

  #syncUndo() {
    $('undo').disabled = !this.undoStack.length;
    $('redo').disabled = !this.redoStack.length;
  }

  // ---- tags -------------------------------------------------------------------------------

  // The sharpness the tag tools give (the field under them): a number > 0, Infinity from 10 on
  // (infinitely sharp: a singular tag), or null (and a message) when the field is not usable.
  #toolSharpness() {
    const s = Number($('tag-sharpness').value);
    if (!Number.isFinite(s) || s <= 0) {
      this.error(`The sharpness must be a number above 0 (10 or more is infinitely sharp); got “${$('tag-sharpness').value}”.`);
      return null;
    }
    return s >= 10 ? Infinity : s;
  }

  // A click of the corner, crease or embedded-surface tool: the simplex gets the tools'
  // sharpness (a singular tag when infinite, a `sharpness` entry otherwise); a click on a
  // simplex that already has that sharpness untags it.
  async toggleTag(simplex) {
    const kind = ['corner', 'crease', 'embedded-surface triangle'][simplex.length - 1];
    const want = this.#toolSharpness();
    if (want === null) return;
    const t = tagsOf(this.model.complex);
    const k = key(simplex);
    const had = t.singular.some((s) => key(s) === k) ? Infinity
      : (t.sharpness || []).find((e) => key(e.simplex) === k)?.value;
    t.singular = t.singular.filter((s) => key(s) !== k);
    if (t.sharpness) t.sharpness = t.sharpness.filter((e) => key(e.simplex) !== k);
    const name = `the ${kind} ${simplex.join('–')}`;
    let what;
    if (had !== undefined && (had === want || Math.abs(had - want) < 1e-6)) {
      what = `Untagging ${name}`;
    } else {
      if (want === Infinity) t.singular.push(simplex);
      else (t.sharpness ||= []).push({ simplex, value: want });
      const s = want === Infinity ? 'infinitely sharp' : `sharpness ${want}`;
      what = had === undefined ? `Tagging ${name} (${s})` : `Setting ${name} to ${s}`;
    }
    await this.setTags(t, what);
  }

  // tags: a PUT /tags body, or a list of singular simplices (no sharpness, no petals).
  async setTags(tags, what) {
    const body = Array.isArray(tags) ? { singular: tags } : tags;
    let answer = null;
    try {
      await this.run(async () => {
        answer = await this.session.putTags(body, what);
        await this.#refreshComplex();
      });
    } catch (e) {
      this.error(e);
      return null;
    }
    await this.requestLevel();
    return answer;
  }

  // Creases by dihedral angle (PUT /tags "crease_angle"): the edges it tags join the singular
  // tags. The page remembers which ones it added, so moving the slider (or unticking the box)
  // first takes those away again; tags set by hand are kept.
  async applyCreaseAngle() {
    if (!this.model) return;
    const on = $('crease-angle-on').checked, deg = Number($('crease-angle').value);
    const t = tagsOf(this.model.complex);
    const mine = this.angleTagged && this.angleTagged.model === this.model ? this.angleTagged.keys : new Set();
    t.singular = t.singular.filter((s) => !mine.has(key(s)));
    const before = new Set(t.singular.map(key));
    if (!on) {
      this.angleTagged = null;
      if (mine.size || this.model.complex.tags?.crease_angle) await this.setTags(t, 'Removing the creases tagged by angle');
      this.#tagsNote();
      return;
    }
    t.crease_angle = deg;
    const answer = await this.setTags(t, `Tagging the edges sharper than ${deg}° as creases`);
    if (!answer) return;
    const added = (this.model.complex.tags?.singular || []).map(key).filter((k) => !before.has(k));
    this.angleTagged = { model: this.model, keys: new Set(added) };
    this.info(`${answer.crease_angle?.tagged ?? added.length} edges have a dihedral angle over ${deg}°; ${added.length} of them were not tagged already.`);
  }

  #tagsNote() {
    const tags = this.model?.complex.tags || {};
    const t = tags.singular || [], sh = tags.sharpness || [];
    const n = [1, 2, 3].map((k) => t.filter((s) => s.length === k).length);
    const parts = [];
    if (t.length) parts.push(`${n[0]} corners, ${n[1]} crease edges, ${n[2]} surface triangles`);
    const semi = sh.filter((e) => e.value > 0 && e.value < 10);
    if (semi.length) {
      const v = semi.map((e) => e.value);
      const lo = Math.min(...v), hi = Math.max(...v);
      parts.push(`${semi.length} semi-sharp (sharpness ${lo === hi ? lo : `${lo}–${hi}`})`);
    }
    if (tags.crease_angle) parts.push(`${tags.crease_angle.tagged} edges over ${tags.crease_angle.degrees}°`);
    $('tags-note').textContent = parts.length ? `Tagged: ${parts.join('; ')}.` : 'No tags.';
  }

  // ---- rules ------------------------------------------------------------------------------

  #syncRuleControls() {
    const r = this.model?.complex.rules || {};
    $('rule-default').value = r.nonmanifold_default || 'G2';
    $('rule-solid').value = r.solid_scheme || 'box';
    $('rule-surface').value = r.surface_weights || 'warren';
    $('rule-nms').value = r.nonmanifold_surface || 'chang-qin';
    $('rule-crease').value = r.crease_method || 'uniform';
  }

  async changeRules(patch, what) {
    const rules = { ...this.model.complex.rules, ...patch };
    try {
      await this.run(async () => {
        await this.session.putRules(rules, what);
        await this.#refreshComplex();
      });
    } catch (e) {
      this.error(e);
      this.#syncRuleControls(); // back to what the daemon has
      if (this.selected && !$('override').hidden) this.#showOverride(this.selected);
      return;
    }
    await this.requestLevel();
  }

  // The rule tool picked a vertex or edge: show what it is and the override editor.
  #showOverride(simplex) {
    this.selected = simplex;
    const c = this.model.complex;
    const cls = simplex.length === 1 ? c.classes.vertices[simplex[0]]
      : c.classes.edges.find((e) => key(e.vertices) === key(simplex));
    const name = simplex.length === 1 ? `vertex ${simplex[0]}` : `edge ${simplex.join('–')}`;
    $('override').hidden = false;
    $('override-what').textContent = cls
      ? `${name}: rule ${cls.rule}, dimensions ${cls.family.join(', ')}, non-manifold type ${cls.nonmanifold}`
      : name;
    const cur = (c.rules.overrides || []).find((o) => key(o.simplex) === key(simplex));
    $('override-rule').value = cur?.rule || '';
    // the daemon takes a rule choice only where parts meet (docs/SERVICE.md, invalid-override)
    const manifold = cls?.nonmanifold === 0;
    for (const opt of $('override-rule').options) opt.disabled = manifold && opt.value !== '';
    $('override-apply').disabled = manifold && !cur;
    if (manifold) $('override-what').textContent += ' — manifold: its part\'s own rule applies';
    const dims = cls?.family || [];
    $('override-dim').replaceChildren(...dims.map((d) => new Option(`${d}`, d)));
    if (cur?.dimension !== undefined) $('override-dim').value = cur.dimension;
    // N2 pairs: two of the (k+1)-simplices through the picked one
    const incident = new Map();
    for (const s of c.simplices) {
      if (!simplex.every((v) => s.includes(v)) || s.length <= simplex.length) continue;
      const rest = s.filter((v) => !simplex.includes(v));
      for (const v of rest) {
        const f = [...simplex, v];
        incident.set(key(f), f);
      }
    }
    const inc = [...incident.values()];
    const pairs = [];
    for (let i = 0; i < inc.length && pairs.length < 60; i++)
      for (let j = i + 1; j < inc.length && pairs.length < 60; j++) pairs.push([inc[i], inc[j]]);
    $('override-pair').replaceChildren(...pairs.map((p) => new Option(p.map((f) => `[${f.join(',')}]`).join(' + '), JSON.stringify(p))));
    this.#overrideFields();
  }

  #overrideFields() {
    const r = $('override-rule').value;
    $('override-dim-field').hidden = r !== 'N1';
    $('override-pair-field').hidden = r !== 'N2';
  }

  async applyOverride() {
    const simplex = this.selected;
    if (!simplex) return;
    const rule = $('override-rule').value;
    const others = (this.model.complex.rules.overrides || []).filter((o) => key(o.simplex) !== key(simplex));
    const o = { simplex, rule };
    if (rule === 'N1') o.dimension = Number($('override-dim').value);
    if (rule === 'N2' && $('override-pair').value) o.pair = JSON.parse($('override-pair').value);
    const overrides = rule ? [...others, o] : others;
    const name = simplex.length === 1 ? `vertex ${simplex[0]}` : `edge ${simplex.join('–')}`;
    await this.changeRules({ overrides }, rule ? `Choosing rule ${rule} for ${name}` : `Restoring the default rule of ${name}`);
  }

  // ---- pointer tools ----------------------------------------------------------------------

  #local(ev) {
    const r = this.viewer.canvas.getBoundingClientRect();
    return { x: ev.clientX - r.left, y: ev.clientY - r.top };
  }

  // Capture phase on the canvas: runs before OrbitControls, and stops it when a point is grabbed.
  onPointerDown(ev) {
    if (ev.button !== 0 || !this.model) return;
    const { x, y } = this.#local(ev);
    this.press = { x, y };
    if (this.tool !== 'move' || !this.viewer.visible.cage) return;
    const v = this.viewer, level = v.handles?.level ?? 0;
    const i = v.handleAt(x, y);
    if (i < 0) return;
    ev.stopImmediatePropagation();
    ev.preventDefault();
    v.canvas.setPointerCapture(ev.pointerId);
    v.controls.enabled = false;
    const from = v.handlePosition(i); // float32, for the drag plane
    const start = level === 0 ? this.model.complex.vertices[i].slice() : from.toArray();
    this.drag = { level, index: i, from, to: null, start };
    this.#fillMoveFields(i, start);
    this.#hint(level ? `Moving point ${i} of level ${level}…` : `Moving control point ${i}…`);
  }

  onPointerMove(ev) {
    if (!this.drag) return;
    const { x, y } = this.#local(ev);
    const p = this.viewer.pointOnViewPlane(x, y, this.drag.from);
    if (!p) return;
    this.drag.to = p;
    this.viewer.moveHandle(this.drag.index, p);
    const what = this.drag.level ? `Moving point ${this.drag.index} of level ${this.drag.level}` : undefined;
    this.queueMove(this.drag.level, this.drag.index, p, what, ev.timeStamp || performance.now());
  }

  onPointerUp(ev) {
    if (this.drag) {
      const d = this.drag;
      this.drag = null;
      this.viewer.controls.enabled = true;
      this.#hint(this.#moveHint()); // not "Moving …" any more
      if (this.viewer.canvas.hasPointerCapture(ev.pointerId)) this.viewer.canvas.releasePointerCapture(ev.pointerId);
      if (d.to && d.to.distanceTo(d.from) > 0) {
        this.undoStack.push({ level: d.level, index: d.index, from: d.start, to: d.to.toArray() });
        this.#fillMoveFields(d.index, d.to.toArray());
        if (this.slice.on) this.requestLevel(); // the slice is not part of a delta
        this.redoStack = [];
        this.#syncUndo();
      }
      return;
    }
    if (!this.press || !this.model || ev.button !== 0) return;
    const { x, y } = this.#local(ev);
    const moved = Math.hypot(x - this.press.x, y - this.press.y);
    this.press = null;
    if (moved > 4 || this.tool === 'move') return; // an orbit, not a click
    this.#click(x, y);
  }

  #click(x, y) {
    const v = this.viewer;
    if (!v.visible.cage) {
      this.info('Show the control cage to pick its vertices, edges and triangles.');
      return;
    }
    if (this.tool === 'corner') {
      const i = v.vertexAt(x, y);
      if (i >= 0) this.toggleTag([i]);
      else this.info('No control vertex there: click on a round control point.');
    } else if (this.tool === 'crease') {
      const e = v.edgeAt(x, y);
      if (e) this.toggleTag([...e]);
      else this.info('No control edge there: click on a line of the control cage.');
    } else if (this.tool === 'surface') {
      const f = v.faceAt(x, y);
      if (f) this.toggleTag([...f]);
      else this.info('No control triangle there.');
    } else if (this.tool === 'rule') {
      const i = v.vertexAt(x, y);
      const e = i < 0 ? v.edgeAt(x, y) : null;
      if (i >= 0) this.#showOverride([i]);
      else if (e) this.#showOverride([...e]);
      else this.info('No control vertex or edge there.');
    }
  }

  setTool(t) {
    this.tool = t;
    this.#hint(TOOL_HINTS[t] + '.');
  }

  // ---- wiring -------------------------------------------------------------------------------

  wire() {
    const sel = $('example');
    for (const ex of EXAMPLES) sel.append(new Option(ex.name, ex.id));
    const loadExample = () => {
      const ex = EXAMPLES.find((e) => e.id === sel.value);
      if (ex) this.loadModel(ex.name, ex.make(), { attribute: ex.attribute });
      else this.info('Choose an example to load (the file shown is the one loaded).');
    };
    sel.addEventListener('change', loadExample);
    $('load-example').addEventListener('click', loadExample);
    $('file').addEventListener('change', (ev) => {
      const f = ev.target.files[0];
      if (f) this.openFile(f);
      ev.target.value = '';
    });
    $('embed-file').addEventListener('change', (ev) => {
      const f = ev.target.files[0];
      if (f) this.embedFile(f);
      ev.target.value = '';
    });
    $('embed-remove').addEventListener('click', () => this.removeEmbedded());
    const view = $('view');
    view.addEventListener('dragover', (ev) => ev.preventDefault());
    view.addEventListener('drop', (ev) => {
      ev.preventDefault();
      const f = ev.dataTransfer?.files?.[0];
      if (f) this.openFile(f);
    });

    $('level').addEventListener('input', (ev) => {
      this.level = Number(ev.target.value);
      $('level-value').textContent = this.level;
      this.requestLevel();
    });
    for (const part of ['cage', 'points', 'curves', 'surfaces', 'solids'])
      $(`show-${part}`).addEventListener('change', (ev) => this.viewer.setVisible(part, ev.target.checked));
    $('show-interior').addEventListener('change', (ev) => this.viewer.setXray(ev.target.checked));
    $('edit-level').addEventListener('change', (ev) => this.setEditLevel(Number(ev.target.value)));

    $('color-mode').addEventListener('change', (ev) => this.setColorMode(ev.target.value));
    for (const id of ['color-min', 'color-max'])
      $(id).addEventListener('change', () => {
        const lo = Number($('color-min').value), hi = Number($('color-max').value);
        if (!(Number.isFinite(lo) && Number.isFinite(hi) && hi > lo) || !$('color-min').value.trim() || !$('color-max').value.trim()) {
          this.error(`The colour range needs min < max (got ${$('color-min').value} and ${$('color-max').value}).`);
          return;
        }
        this.color.min = lo;
        this.color.max = hi;
        this.#legend();
        this.requestLevel();
      });

    $('xsec').addEventListener('change', (ev) => this.setSlice({ on: ev.target.checked }));
    $('xsec-axis').addEventListener('change', (ev) => this.setSlice({ axis: ev.target.value }));
    $('xsec-pos').addEventListener('input', (ev) => this.setSlice({ t: Number(ev.target.value) }));

    for (const r of document.querySelectorAll('input[name=tool]'))
      r.addEventListener('change', (ev) => ev.target.checked && this.setTool(ev.target.value));
    $('undo').addEventListener('click', () => this.undo());
    $('redo').addEventListener('click', () => this.redo());
    $('clear-tags').addEventListener('click', () => {
      if (!this.model) return;
      $('crease-angle-on').checked = false;
      this.angleTagged = null;
      this.setTags([], 'Removing every tag');
    });

    const rule = (id, field, label) => $(id).addEventListener('change', (ev) =>
      this.model && this.changeRules({ [field]: ev.target.value }, `Choosing ${label} ${ev.target.value}`));
    rule('rule-default', 'nonmanifold_default', 'the non-manifold default rule');
    rule('rule-solid', 'solid_scheme', 'the solid scheme');
    rule('rule-surface', 'surface_weights', 'the surface weights');
    rule('rule-nms', 'nonmanifold_surface', 'the non-manifold surface rules');
    rule('rule-crease', 'crease_method', 'the crease method');
    $('crease-angle').addEventListener('input', (ev) => { $('crease-angle-value').textContent = `${ev.target.value}°`; });
    $('crease-angle').addEventListener('change', () => $('crease-angle-on').checked && this.applyCreaseAngle());
    $('crease-angle-on').addEventListener('change', () => this.applyCreaseAngle());
    $('override-rule').addEventListener('change', () => this.#overrideFields());
    $('override-apply').addEventListener('click', () => this.applyOverride());

    const c = this.viewer.canvas;
    c.addEventListener('pointerdown', (ev) => this.onPointerDown(ev), { capture: true });
    // pointerrawupdate (secure contexts: localhost, https) is not held back to the next frame
    // as pointermove is: a drag's PATCH leaves as soon as the mouse moves
    c.addEventListener('onpointerrawupdate' in window ? 'pointerrawupdate' : 'pointermove', (ev) => this.onPointerMove(ev));
    c.addEventListener('pointerup', (ev) => this.onPointerUp(ev));
    c.addEventListener('pointercancel', (ev) => this.onPointerUp(ev));

    $('move-apply').addEventListener('click', () => this.moveExact());
    $('move-index').addEventListener('change', () => {
      const i = Number($('move-index').value);
      if (this.#handlePoint(i)) this.#fillMoveFields(i);
    });
    for (const id of ['move-index', 'move-x', 'move-y', 'move-z']) {
      $(id).addEventListener('input', () => this.#moveFieldsNow()); // typed for these handles
      $(id).addEventListener('keydown', (ev) => {
        if (ev.key !== 'Enter') return;
        ev.preventDefault();
        if (id === 'move-index') $('move-index').dispatchEvent(new Event('change')); // where it is
        else this.moveExact();
      });
    }
    window.addEventListener('keydown', (ev) => {
      if (ev.target.matches?.('input[type=number], input[type=text]')) return;
      const mod = ev.ctrlKey || ev.metaKey;
      if (mod && ev.key.toLowerCase() === 'z') {
        ev.preventDefault();
        if (ev.shiftKey) this.redo();
        else this.undo();
      } else if (mod && ev.key.toLowerCase() === 'y') {
        ev.preventDefault();
        this.redo();
      }
    });
    window.addEventListener('pagehide', () => this.session.shortenOnExit());
    // back from the back/forward cache: the page lives on, so its session gets its TTL back
    window.addEventListener('pageshow', (ev) => {
      if (!ev.persisted || !this.session.owned) return;
      this.session.markLive();
      // gone while the page was away (its 2 minutes passed): replaced, as at the next change
      this.run(() => this.session.setTtl(TTL_S)).catch((e) => this.error(e));
    });
    window.addEventListener('error', (ev) => this.error(ev.error || ev.message));
    window.addEventListener('unhandledrejection', (ev) => this.error(ev.reason));
  }

  // ---- for tests and the curious: window.subdivd ------------------------------------------

  snapshot() {
    const c = this.model?.complex;
    return {
      ready: this.ready,
      idle: this.idle(),
      model: this.model?.name ?? null,
      session: this.session.id,
      version: this.session.version,
      level: this.level,
      maxLevel: this.model?.maxLevel ?? null,
      shown: this.shown && { ...this.shown, geometry: this.#geometryHash() },
      tags: c?.tags?.singular ?? [],
      sharpness: c?.tags?.sharpness ?? [],
      creaseAngle: c?.tags?.crease_angle ?? null,
      rules: c?.rules ?? null,
      vertexRules: c?.classes.vertices.map((v) => v.rule) ?? [],
      edgeRules: c?.classes.edges.map((e) => ({ vertices: e.vertices, rule: e.rule, singular: e.singular })) ?? [],
      controlPoints: c?.vertices ?? [],
      editLevel: this.editLevel,
      handles: this.viewer.handles ? { level: this.viewer.handles.level, count: this.viewer.handles.count } : null,
      known: this.known,
      listening: !!this.events && this.events.readyState === 1,
      perf: { deltas: this.perf.deltas, deltaBytes: this.perf.deltaBytes, refetches: this.perf.refetches, updates: this.perf.updates.length },
      undo: this.undoStack.length,
      redo: this.redoStack.length,
      slicing: this.viewer.slicing,
      embedded: this.embedded && { file: this.embedded.file, version: this.embedded.version, level: this.embedded.level, deltas: this.embedded.deltas, busy: this.embedded.busy },
      messages: this.messages.slice(),
    };
  }

  // The embedded model's drawn positions (float32) and the daemon's (GET /embedded/model).
  async embeddedCompare() {
    const mine = this.viewer.embeddedPositions();
    const j = await this.session.getEmbedded('model');
    const theirs = new Float32Array(j.vertices.flat());
    let differ = 0;
    for (let i = 0; i < theirs.length; i++) if (mine[i] !== theirs[i]) differ++;
    return { version: j.version, count: j.vertices.length, differ, drawn: mine ? mine.length / 3 : 0 };
  }

  // Page coordinates of a control vertex, or of the middle of an edge / triangle.
  screenOf(simplex) {
    const p = new THREE.Vector3();
    for (const i of simplex) p.add(this.viewer.cagePosition(i));
    p.divideScalar(simplex.length);
    const s = this.viewer.toScreen(p);
    const r = this.viewer.canvas.getBoundingClientRect();
    return { x: r.left + s.x, y: r.top + s.y };
  }

  pixels() {
    return this.viewer.pixelStats();
  }

  // A hash of the drawn level's positions (small levels only: snapshot() is polled).
  #geometryHash() {
    const a = this.viewer.level?.positions[0]?.array;
    if (!a || a.length > 600000) return null;
    return fnv1a(new Uint8Array(a.buffer, a.byteOffset, a.byteLength));
  }

  // The drawn level's buffers (POSITION, NORMAL of the shared accessors), for comparing with a
  // fresh GET of the level.
  levelBuffers() {
    const L = this.viewer.level;
    return { position: L?.positions[0]?.array ?? null, normal: L?.normals[0]?.array ?? null, count: L?.count ?? 0, distinct: L ? [L.positions.length, L.normals.length] : [] };
  }

  async start() {
    this.wire();
    window.subdivd = this;
    $('range').hidden = true;
    const ex = EXAMPLES[0];
    const frag = new URLSearchParams(location.hash.slice(1)), kept = Session.kept();
    if (frag.get('session') && frag.get('token')) {
      this.#hint('Joining the session…');
      if (await this.join(frag.get('session'), frag.get('token'), { name: frag.get('name') || undefined })) {
        this.ready = true;
        return;
      }
    } else if (kept && kept.live) {
      // a duplicate of the tab that shows this session: join it as a tab opened by its link
      // would (the session stays the other tab's), with the link in the address for a reload
      Session.forget();
      history.replaceState(null, '', sessionLink(kept.id, kept.token, kept.name));
      this.#hint('Joining the session…');
      if (await this.join(kept.id, kept.token, { name: kept.name, embedded: kept.embedded })) {
        this.ready = true;
        return;
      }
    } else if (kept) { // this tab was reloaded: its session and model, as they were
      this.#hint('Opening this tab\'s session again…');
      if (await this.join(kept.id, kept.token, { owned: true, name: kept.name, embedded: kept.embedded })) {
        this.ready = true;
        return;
      }
    }
    this.#hint(`Loading the example “${ex.name}”…`);
    await this.loadModel(ex.name, ex.make(), { attribute: ex.attribute });
    if (!this.model) this.#hint('The example could not be loaded — the message below says why.');
    this.ready = true;
  }
}

let app;
try {
  app = new App();
} catch (e) {
  document.getElementById('hint').textContent = `The 3D view could not start: ${e.message} (WebGL needed).`;
  throw e;
}
app.start();
