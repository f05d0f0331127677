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

export class Session {
  constructor(base = '') {
    this.base = base; // '' = the origin that served the page
    this.id = null;
    this.token = null;
    this.version = 0;
  }

  async open(ttl_s = 3600) {
    const res = await this.#fetch('Starting a session', '/v1/sessions', {
      method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify({ ttl_s }),
    });
    const j = await res.json();
    this.id = j.id;
    this.token = j.token;
    this.version = 0;
    return j;
  }

  // Best effort at page exit (keepalive survives the unload); the TTL frees it otherwise.
  closeOnExit() {
    if (!this.id) return;
    fetch(`${this.base}/v1/sessions/${this.id}`, {
      method: 'DELETE', keepalive: true, headers: { Authorization: `Bearer ${this.token}` },
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
    if (tag && /^"\d+"$/.test(tag)) this.version = Number(tag.slice(1, -1));
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
    if (typeof j.version === 'number') this.version = j.version;
    return j;
  }

  putComplex(body) {
    return this.json('Posting the control complex', 'PUT', '/complex', { body });
  }

  getComplex() {
    return this.json('Reading the control complex', 'GET', '/complex');
  }

  putTags(singular, what = 'Tagging') {
    return this.json(what, 'PUT', '/tags', { body: { singular } });
  }

  putRules(rules, what = 'Changing the rules') {
    return this.json(what, 'PUT', '/rules', { body: rules });
  }

  moveControlPoints(moves, what = 'Moving a control point') {
    return this.json(what, 'PATCH', '/control-points', { body: { moves }, ifMatch: this.version });
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
