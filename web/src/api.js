// The daemon's HTTP API as the front end uses it (docs/SERVICE.md, api/openapi.json).
//
// A Session owns one daemon session: its id, bearer token and the version the daemon last
// reported (the ETag of every change; edits send it back as If-Match). Every failure becomes an
// ApiError whose message is a sentence for the user, built from the problem+json `detail` and
// the JSON pointers of `errors[]` — nothing is swallowed here; callers show it.

export class ApiError extends Error {
  constructor(what, status, problem) {
    super(describe(what, status, problem));
    this.name = 'ApiError';
    this.status = status;
    this.problem = problem || {};
  }

  get type() {
    return this.problem.type || '';
  }
}

function describe(what, status, p) {
  if (!status) return `${what} failed: the daemon could not be reached (${p?.detail || 'network error'}).`;
  const title = p?.title || `HTTP ${status}`;
  let s = `${what} failed — ${status} ${title}`;
  if (status === 501) s += ' (this version of the daemon does not implement it yet)';
  if (p?.detail) s += `: ${p.detail}`;
  const where = (p?.errors || []).map((e) => e.pointer).filter((x) => x && x !== '');
  if (where.length) s += ` (at ${[...new Set(where)].slice(0, 4).join(', ')})`;
  return s.endsWith('.') ? s : s + '.';
}

async function problemOf(res) {
  const text = await res.text();
  try {
    return JSON.parse(text);
  } catch {
    return { detail: text.slice(0, 300) || res.statusText };
  }
}

// The tab's own session, kept over a reload: sessionStorage is per tab and outlives a reload,
// not the tab.
const KEPT = 'subdivd.session';
// Set while the tab that started the session shows it, cleared as its page goes: a tab that
// finds it set at load is a duplicate (a duplicated tab gets a copy of sessionStorage), and the
// session is the other tab's.
const LIVE = 'subdivd.live';
export const TTL_S = 3600; // idle TTL while the page is open
export const AWAY_TTL_S = 120; // after the page went: long enough for a reload, short after a close

export class Session {
  constructor(base = '') {
    this.base = base; // '' = the origin that served the page
    this.id = null;
    this.token = null;
    this.version = 0;
    this.owned = false; // started by this tab (open), not joined: only then its TTL is this tab's
  }

  async open(ttl_s = TTL_S) {
    const res = await this.#fetch('Starting a session', '/v1/sessions', {
      method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify({ ttl_s }),
    });
    const j = await res.json();
    this.id = j.id;
    this.token = j.token;
    this.version = j.version ?? 0;
    this.owned = true;
    this.keep();
    this.markLive();
    return j;
  }

  // The session this tab started before a reload ({id, token, name, live}), or null; `live`:
  // still marked as shown (this tab is a duplicate of the one that shows it).
  static kept() {
    try {
      const j = JSON.parse(sessionStorage.getItem(KEPT));
      if (typeof j?.id !== 'string' || typeof j?.token !== 'string') return null;
      return { ...j, live: sessionStorage.getItem(LIVE) === j.id };
    } catch {
      return null; // storage off or damaged: nothing kept
    }
  }

  markLive() {
    if (!this.owned) return;
    try { sessionStorage.setItem(LIVE, this.id); } catch { /* storage off */ }
  }

  // Remember this tab's own session (and the name of its model) for a reload.
  keep(name) {
    if (!this.owned) return;
    const was = Session.kept();
    try {
      sessionStorage.setItem(KEPT, JSON.stringify({ id: this.id, token: this.token, name: name ?? (was?.id === this.id ? was.name : undefined) }));
    } catch { /* storage off: a reload starts afresh */ }
  }

  // The name of the file embedded in this tab's session (null: none), kept for a reload.
  keepEmbedded(file) {
    const was = Session.kept();
    if (!this.owned || was?.id !== this.id) return;
    try {
      sessionStorage.setItem(KEPT, JSON.stringify({ ...was, live: undefined, embedded: file ?? undefined }));
    } catch { /* storage off */ }
  }

  listEmbedded() {
    return this.json('Reading the embedded models', 'GET', '/embedded');
  }

  static forget() {
    try {
      sessionStorage.removeItem(KEPT);
      sessionStorage.removeItem(LIVE);
    } catch { /* storage off */ }
  }

  // PATCH /v1/sessions/{id} {"ttl_s"}: the session's idle TTL from now.
  setTtl(ttl_s) {
    return this.json('Keeping the session', 'PATCH', '', { body: { ttl_s } });
  }

  // At page exit the tab's own session gets a short TTL instead of a delete (keepalive survives
  // the unload): a reload finds it and sets the TTL back, a closed tab's goes 2 minutes later.
  // A session another tab started (joined by its link) is that tab's: left as it is.
  shortenOnExit() {
    if (!this.id || !this.owned) return;
    try { sessionStorage.removeItem(LIVE); } catch { /* storage off */ }
    fetch(`${this.base}/v1/sessions/${this.id}`, {
      method: 'PATCH', keepalive: true, body: JSON.stringify({ ttl_s: AWAY_TTL_S }),
      headers: { Authorization: `Bearer ${this.token}`, 'Content-Type': 'application/json' },
    }).catch(() => {}); // the page is going away: there is no one left to tell
  }

  async #fetch(what, path, init = {}) {
    let res;
    try {
      res = await fetch(this.base + path, { cache: 'no-store', ...init });
    } catch (e) {
      throw new ApiError(what, 0, { detail: e.message });
    }
    if (!res.ok) throw new ApiError(what, res.status, await problemOf(res));
    const tag = res.headers.get('ETag');
    // versions only grow; a read answered before a change may arrive after that change's answer
    if (tag && /^"\d+"$/.test(tag)) this.version = Math.max(this.version, Number(tag.slice(1, -1)));
    return res;
  }

  // A request under /v1/sessions/{id}; `what` names it in error messages.
  async request(what, method, sub, { body, ifMatch, query } = {}) {
    const headers = { Authorization: `Bearer ${this.token}` };
    if (body !== undefined) headers['Content-Type'] = 'application/json';
    if (ifMatch !== undefined) headers['If-Match'] = `"${ifMatch}"`;
    const q = query ? '?' + new URLSearchParams(query).toString() : '';
    return this.#fetch(what, `/v1/sessions/${this.id}${sub}${q}`, {
      method, headers, body: body === undefined ? undefined : JSON.stringify(body),
    });
  }

  async json(what, method, sub, opts) {
    const res = await this.request(what, method, sub, opts);
    const j = await res.json();
    if (typeof j.version === 'number') this.version = Math.max(this.version, j.version);
    return j;
  }

  putComplex(body) {
    return this.json('Posting the control complex', 'PUT', '/complex', { body });
  }

  getComplex() {
    return this.json('Reading the control complex', 'GET', '/complex');
  }

  // tags: {singular, petals?, sharpness?, crease_angle?} (a PUT replaces every tag).
  putTags(tags, what = 'Tagging') {
    return this.json(what, 'PUT', '/tags', { body: tags });
  }

  putRules(rules, what = 'Changing the rules') {
    return this.json(what, 'PUT', '/rules', { body: rules });
  }

  // moves: [{index, position, level?}] (level ≥ 1: a detail offset at that level).
  moveControlPoints(moves, what = 'Moving a control point') {
    return this.json(what, 'PATCH', '/control-points', { body: { moves }, ifMatch: this.version });
  }

  // The same edit answered with its delta of level `level` (PATCH ?delta=, one round trip):
  // {version, updated_points, delta} where delta is parseDelta's object (since = the version
  // the edit was made on), or null when the daemon could not make it (then `gone` says why and
  // the caller brings the level up to date another way).
  async moveControlPointsDelta(moves, level, what = 'Moving a control point') {
    const res = await this.request(what, 'PATCH', '/control-points',
      { body: { moves }, ifMatch: this.version, query: { delta: level } });
    const up = res.headers.get('X-Updated-Points');
    if ((res.headers.get('Content-Type') || '').startsWith('application/octet-stream')) {
      const delta = parseDelta(await res.arrayBuffer());
      this.version = Math.max(this.version, delta.version);
      return { version: delta.version, updated_points: up ? JSON.parse(up) : {}, delta };
    }
    const j = await res.json(); // the summary, with the problem that kept the delta from being made
    if (typeof j.version === 'number') this.version = Math.max(this.version, j.version);
    return { version: j.version, updated_points: j.updated_points, delta: null, gone: j.delta };
  }

  // The level-L points that changed after version `since` (API.md "Live edits", the binary
  // "SDD1" layout): {level, since, version, n, indices, positions, normals|null, bytes}. A 410
  // (the change was not an edit, the level is not cached, ...) is an ApiError with status 410:
  // the caller fetches the level again.
  async delta(level, since) {
    const res = await this.request(`Updating level ${level}`, 'GET', `/levels/${level}/delta`,
      { query: { since, format: 'bin' } });
    return parseDelta(await res.arrayBuffer());
  }

  // Server-Sent Events of the session (EventSource cannot send headers: ?access_token=).
  // handlers: {version(data, id), resync(), deleted(), error(ev)}. Returns the EventSource.
  events(handlers) {
    const q = new URLSearchParams({ access_token: this.token });
    const es = new EventSource(`${this.base}/v1/sessions/${this.id}/events?${q}`);
    const dataOf = (ev) => {
      try {
        return JSON.parse(ev.data) ?? {};
      } catch {
        return {};
      }
    };
    es.addEventListener('version', (ev) => {
      const data = dataOf(ev);
      handlers.version?.(data, Number(ev.lastEventId || data.version));
    });
    es.addEventListener('resync', () => handlers.resync?.());
    es.addEventListener('deleted', (ev) => handlers.deleted?.(dataOf(ev)));
    es.onerror = (ev) => handlers.error?.(ev, es);
    return es;
  }

  // Embedded models (free-form deformation): bind, read, follow, remove.
  putEmbedded(name, body) {
    return this.json(`Embedding ${name}`, 'PUT', `/embedded/${name}`, { body, ifMatch: this.version });
  }

  getEmbedded(name) {
    return this.json(`Reading ${name}`, 'GET', `/embedded/${name}`);
  }

  async embeddedDelta(name, since) {
    const res = await this.request(`Updating ${name}`, 'GET', `/embedded/${name}/delta`, { query: { since, format: 'bin' } });
    return parseDelta(await res.arrayBuffer());
  }

  async deleteEmbedded(name) {
    await this.request(`Removing ${name}`, 'DELETE', `/embedded/${name}`, { ifMatch: this.version });
  }

  stats(level) {
    return this.json(`Reading the statistics of level ${level}`, 'GET', `/levels/${level}/stats`);
  }

  // The level as GLB bytes; query: slice, colormap, parts, attributes.
  async levelGlb(level, query) {
    const res = await this.request(`Fetching level ${level}`, 'GET', `/levels/${level}`, { query });
    return res.arrayBuffer();
  }
}

// "SDD1", uint32 level, since, version, n, flags (bit 0 normals, bit 1 attributes), n uint32
// indices, n×3 float32 positions, n×3 float32 normals if bit 0 (attributes are not asked for).
export function parseDelta(buf) {
  const dv = new DataView(buf);
  const magic = String.fromCharCode(...new Uint8Array(buf, 0, Math.min(4, buf.byteLength)));
  if (buf.byteLength < 24 || magic !== 'SDD1') throw new Error(`not an SDD1 delta (${buf.byteLength} bytes)`);
  const [level, since, version, n, flags] = [4, 8, 12, 16, 20].map((o) => dv.getUint32(o, true));
  const need = 24 + n * 4 + n * 12 + (flags & 1 ? n * 12 : 0);
  if (buf.byteLength < need) throw new Error(`short SDD1 delta: ${buf.byteLength} bytes, ${need} needed for ${n} points`);
  // little endian on every platform a browser runs on; the offsets are multiples of 4
  const indices = new Uint32Array(buf, 24, n);
  const positions = new Float32Array(buf, 24 + 4 * n, 3 * n);
  const normals = flags & 1 ? new Float32Array(buf, 24 + 16 * n, 3 * n) : null;
  return { level, since, version, n, flags, indices, positions, normals, bytes: buf.byteLength };
}
