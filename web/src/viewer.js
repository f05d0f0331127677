// The three.js view: one subdivided level (the GLB the daemon streams), the control cage (the
// posted complex, from GET /complex) on top of it, an optional cross-section plane, and the
// screen-space picking the tools need. It knows nothing of HTTP; main.js feeds it.
//
// Level GLB layout (docs/OUTPUTS.md): a root node "level L" with one child node per part, each
// with its own mesh of one primitive, node and mesh named after the part: points, curves,
// surfaces, solids, slice (empty ones left out). GLTFLoader gives each its node's name.
// COLOR_0 is linear (glTF 2.0 3.7.2.1) as three.js's vertex colours are; the renderer's output
// colour space (sRGB) does the rest.
//
// Live edits: every primitive indexes the one POSITION (and NORMAL) accessor, whose order is the
// level's vertex order, so a delta (api.js parseDelta) is written in place at its indices
// (applyDelta) and only the changed ranges go to the GPU. The move tool drags "handles": the
// control points (level 0) or the points of a finer level. A handle behind the drawn surface is
// neither drawn nor picked (a depth test against the surface, biased by `tol` so points on it
// count as in front; drawn: the depth test, shifted; picked: a ray against the surface's
// triangles); a solid's interior handles are drawn over it only when asked (setXray).
// Drawing is on demand, once per animation frame (requestRender), and can be paused.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { LineSegments2 } from 'three/addons/lines/LineSegments2.js';
import { LineSegmentsGeometry } from 'three/addons/lines/LineSegmentsGeometry.js';
import { LineMaterial } from 'three/addons/lines/LineMaterial.js';
import { ruleColor, sharpnessColor, NO_SHARPNESS } from './colors.js';

const simplexKey = (s) => [...s].sort((a, b) => a - b).join(',');

export const BACKGROUND = 0x1e2229;
const PLAIN = { points: 0xffffff, curves: 0xffa94d, surfaces: 0xc9d6c4, solids: 0xb8c7e0 };
const SLICE = 0xff8c42; // the cross-section's own colour (not the solids')
const PARTS = ['points', 'curves', 'surfaces', 'solids', 'slice']; // node names of a level GLB
const TAG = 0xffffff;

function discTexture() {
  const c = document.createElement('canvas');
  c.width = c.height = 64;
  const g = c.getContext('2d');
  g.beginPath();
  g.arc(32, 32, 28, 0, 2 * Math.PI);
  g.fillStyle = '#fff';
  g.fill();
  g.lineWidth = 6;
  g.strokeStyle = '#222';
  g.stroke();
  const t = new THREE.CanvasTexture(c);
  t.colorSpace = THREE.SRGBColorSpace;
  return t;
}

// Per-vertex colours (linear) of a rule id attribute.
function colorsFromRules(ruleAttr) {
  const out = new Float32Array(ruleAttr.count * 3);
  for (let i = 0; i < ruleAttr.count; i++) ruleColor(Math.round(ruleAttr.getX(i))).toArray(out, 3 * i);
  return new THREE.BufferAttribute(out, 3);
}

// A points material whose points move `bias` towards the eye (along the line of sight, so they
// stay where they are on screen) before the depth test: handles on the surface are drawn, those deeper than `bias` behind it are hidden.
function handleMaterial(opts, bias) {
  const m = new THREE.PointsMaterial({ sizeAttenuation: false, alphaTest: 0.5, ...opts });
  m.userData.bias = { value: bias };
  m.onBeforeCompile = (sh) => {
    sh.uniforms.depthBias = m.userData.bias;
    sh.vertexShader = 'uniform float depthBias;\n' + sh.vertexShader.replace('#include <project_vertex>',
      'vec4 mvPosition = modelViewMatrix * vec4( transformed, 1.0 );\n' +
      'mvPosition.xyz *= max( 0.0, 1.0 - depthBias / length( mvPosition.xyz ) );\n' +
      'gl_Position = projectionMatrix * mvPosition;');
  };
  return m;
}

// Runs of sorted indices, gaps of up to `gap` merged: [start, count] pairs (elements = 3 per index).
function indexRuns(ix, gap = 16) {
  const runs = [];
  let a = ix[0], b = ix[0];
  for (let k = 1; k < ix.length; k++) {
    const i = ix[k];
    if (i < b) return null; // not sorted: upload all
    if (i - b > gap) {
      runs.push([a, b - a + 1]);
      a = i;
    }
    b = i;
  }
  runs.push([a, b - a + 1]);
  return runs;
}

function markRanges(attr, runs) {
  attr.clearUpdateRanges();
  if (runs) for (const [a, n] of runs) attr.addUpdateRange(a * attr.itemSize, n * attr.itemSize);
  attr.needsUpdate = true;
}

// Expand an indexed LINES geometry into the pairs LineSegmentsGeometry wants.
function segmentArrays(geom, colorAttr) {
  const idx = geom.index, pos = geom.attributes.position;
  const n = idx ? idx.count : pos.count;
  const p = new Float32Array(n * 3), c = new Float32Array(n * 3);
  for (let k = 0; k < n; k++) {
    const i = idx ? idx.getX(k) : k;
    p[3 * k] = pos.getX(i); p[3 * k + 1] = pos.getY(i); p[3 * k + 2] = pos.getZ(i);
    if (colorAttr) { c[3 * k] = colorAttr.getX(i); c[3 * k + 1] = colorAttr.getY(i); c[3 * k + 2] = colorAttr.getZ(i); }
  }
  return { p, c };
}

export class Viewer {
  constructor(container) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({ antialias: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.setClearColor(BACKGROUND);
    this.renderer.localClippingEnabled = true;
    container.appendChild(this.renderer.domElement);
    this.canvas = this.renderer.domElement;
    // for assistive technology an image with a description (kept current by the page), and in
    // the tab order: focused, the arrow keys pan the view (OrbitControls' keys)
    this.canvas.setAttribute('role', 'img');
    this.canvas.setAttribute('aria-label', '3D view: no model yet');
    this.canvas.tabIndex = 0;

    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 100);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(4, -6, 3);
    this.scene.add(this.camera);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 1.4));
    const head = new THREE.DirectionalLight(0xffffff, 1.8);
    head.position.set(1, 2, 3);
    this.camera.add(head);

    this.controls = new OrbitControls(this.camera, this.canvas);
    this.controls.listenToKeyEvents(this.canvas);
    this.controls.addEventListener('change', () => {
      this.#orientClip();
      this.render();
    });

    this.levelGroup = new THREE.Group();
    this.cageGroup = new THREE.Group();
    this.handleGroup = new THREE.Group(); // handles of a level ≥ 1
    this.scene.add(this.levelGroup, this.cageGroup, this.handleGroup);
    this.parts = {}; // points, curves, surfaces, solids, slice -> Object3D
    this.visible = { cage: true, points: true, curves: true, surfaces: true, solids: true };
    this.colorMode = 'rule';
    this.clipPlane = new THREE.Plane(new THREE.Vector3(0, 0, -1), 0);
    this.slicing = false;
    this.disc = discTexture();
    this.planeHelper = null;
    this.cage = null;
    this.level = null; // {positions, normals: BufferAttribute[], count}
    this.handles = null; // what the move tool drags: {level, pos, count, interior, tol, objects}
    this.xray = false; // draw (and pick) a solid's interior handles over its surface
    this.paused = false;
    this.rafId = 0;
    this.renders = 0;
    this.renderMs = 0;

    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  resize() {
    const w = Math.max(1, this.container.clientWidth), h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h, false);
    this.canvas.style.width = w + 'px';
    this.canvas.style.height = h + 'px';
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  render() {
    const t = performance.now();
    this.renderer.render(this.scene, this.camera);
    this.renders++;
    this.renderMs += performance.now() - t; // CPU side (the GPU may finish later)
  }

  // Draw once at the next animation frame (however many changes come before it); nothing is
  // drawn while paused (a benchmark times the updates alone), resume() draws what is pending.
  requestRender() {
    this.dirty = true;
    if (this.paused || this.rafId) return;
    this.rafId = requestAnimationFrame(() => {
      this.rafId = 0;
      if (this.dirty && !this.paused) {
        this.dirty = false;
        this.render();
      }
    });
  }

  pause() {
    this.paused = true;
  }

  resume() {
    this.paused = false;
    if (this.dirty) this.requestRender();
  }

  // Aim the camera at a bounding box (on a new model).
  frame(box) {
    const c = box.getCenter(new THREE.Vector3());
    const r = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-6);
    const dist = r / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2)) * 0.9;
    const dir = new THREE.Vector3(0.55, -0.75, 0.42).normalize();
    this.camera.position.copy(c).addScaledVector(dir, dist);
    this.camera.near = dist / 100;
    this.camera.far = dist * 100;
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(c);
    this.controls.update();
    this.bbox = box.clone();
    this.render();
  }

  // ---- the level --------------------------------------------------------------------------

  // gltf: GLTFLoader result; stats: GET /levels/L/stats of the same level.
  setLevel(gltf, stats) {
    for (const o of Object.values(this.parts)) {
      o.geometry?.dispose();
      o.material?.dispose();
    }
    this.levelGroup.clear();
    this.parts = {};
    const prims = [];
    gltf.scene.traverse((o) => { if ((o.isMesh || o.isPoints || o.isLine) && PARTS.includes(o.name)) prims.push(o); });
    for (const o of prims) {
      this.parts[o.name] = this.#makePart(o.name, o.geometry);
      o.material?.dispose();
    }
    for (const o of Object.values(this.parts)) {
      o.frustumCulled = false; // deltas move vertices; the bounds are not kept up to date
      this.levelGroup.add(o);
    }
    // the shared POSITION / NORMAL accessors (one BufferAttribute each in GLTFLoader's cache;
    // every distinct one is kept, should a loader ever copy them)
    const positions = new Set(), normals = new Set();
    for (const o of prims) {
      const g = o.geometry;
      if (o.name === 'slice') continue; // the slice has its own vertices
      if (g.attributes.position) positions.add(g.attributes.position);
      if (g.attributes.normal) normals.add(g.attributes.normal);
    }
    const count = positions.size ? [...positions][0].count : 0;
    this.level = { positions: [...positions], normals: [...normals], count, prims };
    this.applyColors();
    this.applyVisibility();
    this.applyClipping();
    this.render();
  }

  #makePart(part, g) {
    g.userData.ruleColors = g.attributes._rule ? colorsFromRules(g.attributes._rule) : null;
    g.userData.attrColors = g.attributes.color || null; // COLOR_0: linear already
    g.deleteAttribute('color');
    if (part === 'points') {
      const m = new THREE.PointsMaterial({ size: 6, sizeAttenuation: false, map: this.disc, alphaTest: 0.5 });
      return new THREE.Points(g, m);
    }
    if (part === 'curves') {
      const lg = new LineSegmentsGeometry();
      const m = new LineMaterial({ linewidth: 3, worldUnits: false });
      const line = new LineSegments2(lg, m);
      line.userData.source = g;
      return line;
    }
    const m = new THREE.MeshStandardMaterial({
      side: THREE.DoubleSide, roughness: 0.75, metalness: 0, flatShading: false,
      polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
    });
    if (part === 'slice') m.color.setHex(SLICE);
    return new THREE.Mesh(g, m);
  }

  setColorMode(mode) {
    this.colorMode = mode;
    this.applyColors();
    if (this.cage) {
      this.#fillCageColors();
      this.cage.colAttr.needsUpdate = true;
      this.cage.edgeLines.geometry.setColors(this.cage.edgeColors);
      this.requestRender();
    }
  }

  // The cage's vertex and edge colours: by rule family, or (colour mode "sharpness") by the
  // sharpness of each vertex and edge (grey without one).
  #fillCageColors() {
    const { vrule, edges, sharp, colors, edgeColors: ec } = this.cage;
    const bySharp = this.colorMode === 'sharpness';
    const colorOf = (simplex, rule) => {
      if (!bySharp) return ruleColor(rule);
      const s = sharp.get(simplexKey(simplex));
      return s === undefined ? NO_SHARPNESS : sharpnessColor(s);
    };
    vrule.forEach((r, i) => colorOf([i], r).toArray(colors, 3 * i));
    edges.forEach((e, k) => { const c = colorOf(e.v, e.rule); c.toArray(ec, 6 * k); c.toArray(ec, 6 * k + 3); });
  }

  applyColors() {
    for (const [part, o] of Object.entries(this.parts)) {
      const g = o.userData.source || o.geometry;
      if (part === 'slice') { // its own colour; the attribute's when colouring by one
        const colors = this.colorMode === 'attribute' ? g.userData.attrColors : null;
        if (colors) g.setAttribute('color', colors);
        else g.deleteAttribute('color');
        o.material.vertexColors = !!colors;
        o.material.color.setHex(colors ? 0xffffff : SLICE);
        o.material.needsUpdate = true;
        continue;
      }
      const colors = this.colorMode === 'rule' ? g.userData.ruleColors
        : this.colorMode === 'attribute' ? g.userData.attrColors : null;
      if (part === 'curves') {
        const { p, c } = segmentArrays(g, colors);
        o.geometry.dispose();
        o.geometry = new LineSegmentsGeometry().setPositions(p);
        if (colors) o.geometry.setColors(c);
        o.material.vertexColors = !!colors;
        o.material.color.setHex(colors ? 0xffffff : PLAIN.curves);
        o.material.needsUpdate = true;
        continue;
      }
      if (colors) g.setAttribute('color', colors);
      else g.deleteAttribute('color');
      o.material.vertexColors = !!colors;
      o.material.color.setHex(colors ? 0xffffff : PLAIN[part]);
      o.material.needsUpdate = true;
    }
    this.render();
  }

  setVisible(what, on) {
    this.visible[what] = on;
    this.applyVisibility();
    this.render();
  }

  applyVisibility() {
    for (const [part, o] of Object.entries(this.parts)) o.visible = part === 'slice' ? this.slicing : this.visible[part];
    this.cageGroup.visible = this.visible.cage;
    this.handleGroup.visible = this.visible.cage;
  }

  // The cross-section plane n·x = d (n any length), or null for none. The half on the camera's
  // side is cut away (and swaps as the camera orbits), so the slice faces the viewer.
  setSlice(n, d) {
    this.slicing = !!n;
    if (this.planeHelper) {
      this.scene.remove(this.planeHelper);
      this.planeHelper.geometry.dispose();
      this.planeHelper.material.dispose();
      this.planeHelper = null;
    }
    if (n) {
      const u = new THREE.Vector3(...n);
      const len = u.length();
      u.divideScalar(len);
      this.slicePlane = new THREE.Plane(u.clone(), -d / len); // distance = u·x - d/|n|
      this.#orientClip();
      const box = this.bbox || new THREE.Box3(new THREE.Vector3(-1, -1, -1), new THREE.Vector3(1, 1, 1));
      const c = box.getCenter(new THREE.Vector3());
      const size = box.getSize(new THREE.Vector3()).length() * 0.8;
      const at = c.clone().addScaledVector(u, d / len - u.dot(c));
      const m = new THREE.MeshBasicMaterial({ color: SLICE, transparent: true, opacity: 0.12, side: THREE.DoubleSide, depthWrite: false });
      this.planeHelper = new THREE.Mesh(new THREE.PlaneGeometry(size, size), m);
      this.planeHelper.position.copy(at);
      this.planeHelper.quaternion.setFromUnitVectors(new THREE.Vector3(0, 0, 1), u);
      this.scene.add(this.planeHelper);
    }
    this.applyClipping();
    this.applyVisibility();
    this.render();
  }

  // The plane cuts the solid boundary (the slice primitive closes it) and the surfaces, so
  // internal walls show; curves and points stay whole.
  // Keep the half of the cut away from the camera: three clips where the plane's distance < 0.
  #orientClip() {
    if (!this.slicePlane) return;
    const camSide = this.slicePlane.distanceToPoint(this.camera.position);
    this.clipPlane.copy(this.slicePlane);
    if (camSide > 0) this.clipPlane.negate();
  }

  applyClipping() {
    for (const part of ['solids', 'surfaces']) {
      const o = this.parts[part];
      if (!o) continue;
      o.material.clippingPlanes = this.slicing ? [this.clipPlane] : null;
      o.material.needsUpdate = true;
    }
  }

  // Write a delta (api.js parseDelta) into the level's buffers in place; only the changed ranges
  // are uploaded at the next draw. Throws when the delta does not fit the level (the caller
  // fetches the level again).
  applyDelta(d) {
    const L = this.level;
    if (!L || !L.positions.length) throw new Error('no level to update');
    const { n, indices: ix, positions: p, normals: nn } = d;
    if (!n) return;
    for (let k = 0; k < n; k++) if (ix[k] >= L.count) throw new Error(`delta index ${ix[k]} past the level's ${L.count} vertices`);
    const runs = indexRuns(ix);
    const write = (attr, src) => {
      const a = attr.array;
      for (let k = 0; k < n; k++) {
        const o = 3 * ix[k], q = 3 * k;
        a[o] = src[q];
        a[o + 1] = src[q + 1];
        a[o + 2] = src[q + 2];
      }
      markRanges(attr, runs);
    };
    for (const attr of L.positions) write(attr, p);
    if (nn) for (const attr of L.normals) write(attr, nn);
    this.#refreshCurves();
    this.requestRender();
  }

  // An embedded model (free-form deformation): its own mesh, drawn in its own material over the
  // solid; positions n×3 (float32), triangles k×3 (none: points). null removes it.
  setEmbedded(positions, triangles) {
    if (this.embedded) {
      this.scene.remove(this.embedded);
      this.embedded.geometry.dispose();
      this.embedded.material.dispose();
      this.embedded = null;
    }
    if (positions) {
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(positions, 3));
      let o;
      if (triangles && triangles.length) {
        g.setIndex(new THREE.BufferAttribute(triangles, 1));
        g.computeVertexNormals();
        // drawn over the solid (depth test off): a model embedded in a solid is inside it
        o = new THREE.Mesh(g, new THREE.MeshStandardMaterial({ color: 0xf58231, roughness: 0.5, metalness: 0.1, side: THREE.DoubleSide, depthTest: false, transparent: true, opacity: 0.9 }));
      } else {
        o = new THREE.Points(g, new THREE.PointsMaterial({ color: 0xf58231, size: 4, sizeAttenuation: false, depthTest: false }));
      }
      o.name = 'embedded';
      o.renderOrder = 2;
      this.embedded = o;
      this.scene.add(o);
    }
    this.requestRender();
  }

  // The embedded model's vertices that moved (an embedded delta: indices, positions).
  moveEmbedded(d) {
    const o = this.embedded;
    if (!o || !d.n) return;
    const a = o.geometry.attributes.position;
    for (let k = 0; k < d.n; k++) a.array.set(d.positions.subarray(3 * k, 3 * k + 3), 3 * d.indices[k]);
    a.needsUpdate = true;
    if (o.isMesh) o.geometry.computeVertexNormals();
    this.requestRender();
  }

  embeddedPositions() {
    return this.embedded ? Array.from(this.embedded.geometry.attributes.position.array) : null;
  }

  // The curves are drawn as expanded segment pairs (LineSegments2): copy their ends again.
  #refreshCurves() {
    const o = this.parts.curves;
    if (!o) return;
    const { p } = segmentArrays(o.userData.source, null);
    const ib = o.geometry.attributes.instanceStart?.data;
    if (ib && ib.array.length === p.length) {
      ib.array.set(p);
      ib.needsUpdate = true;
    } else {
      this.applyColors();
    }
  }

  // The level's vertex positions (one BufferAttribute; 3 floats per vertex), for handles.
  levelPositions() {
    return this.level?.positions[0] ?? null;
  }

  // Which vertices of a loaded level no primitive draws (a solid's interior points).
  static interiorOf(count, prims) {
    const used = new Uint8Array(count);
    for (const o of prims) {
      const g = o.geometry, idx = g.index;
      if (!g.attributes._rule && !idx) continue; // the slice
      if (idx) for (let k = 0; k < idx.count; k++) used[idx.array[k]] = 1;
      else used.fill(1);
    }
    for (let i = 0; i < count; i++) used[i] ^= 1;
    return used; // 1 = interior
  }

  // ---- the handles: the points the move tool drags ----------------------------------------

  // level 0: the control cage's points (setCage builds them); level ≥ 1: `attr` holds the
  // level's positions (the shown level's own attribute, or one of a level fetched for this),
  // `interior` marks the points no primitive draws.
  setHandles(level, attr, interior) {
    this.#dropHandles();
    if (level === 0 || !attr) {
      this.handles = this.cage ? this.cage.handles : null;
      this.#applyXray();
      this.requestRender();
      return;
    }
    const count = attr.count;
    const tol = (this.cage?.tol ?? 0.05) / 2 ** level;
    const geo = () => {
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', attr);
      return g;
    };
    const front = new THREE.Points(geo(), handleMaterial({ size: 7, color: 0xffd166, map: this.disc }, tol));
    const over = new THREE.Points(geo(), handleMaterial({ size: 7, color: 0xffd166, map: this.disc, depthTest: false, opacity: 0.6, transparent: true }, 0));
    for (const o of [front, over]) {
      o.frustumCulled = false;
      o.renderOrder = 11;
    }
    this.handles = { level, attr, pos: attr.array, count, interior, tol, front, over, own: true };
    this.handleGroup.add(front, over);
    this.#applyXray();
    this.requestRender();
  }

  #dropHandles() {
    const h = this.handles;
    if (!h?.own) return;
    for (const o of [h.front, h.over]) {
      this.handleGroup.remove(o);
      o.geometry.dispose();
      o.material.dispose();
    }
    this.handles = null;
  }

  // Interior handles drawn over the surface (and pickable through it), or depth tested.
  setXray(on) {
    this.xray = on;
    this.#applyXray();
    this.requestRender();
  }

  #applyXray() {
    const h = this.handles;
    if (!h) return;
    const front = [], over = [];
    for (let i = 0; i < h.count; i++) (this.xray && h.interior[i] ? over : front).push(i);
    h.front.geometry.setIndex(front);
    h.over.geometry.setIndex(over);
    h.over.visible = over.length > 0;
  }

  handlePosition(i) {
    return new THREE.Vector3().fromArray(this.handles.pos, 3 * i);
  }

  // Move handle i in the drawing (level 0: the cage; level ≥ 1: the level's point, which the
  // delta then confirms).
  moveHandle(i, p) {
    const h = this.handles;
    if (h.level === 0) return this.moveCageVertex(i, p);
    h.pos[3 * i] = p.x;
    h.pos[3 * i + 1] = p.y;
    h.pos[3 * i + 2] = p.z;
    markRanges(h.attr, [[i, 1]]);
    this.requestRender();
  }

  handleAt(x, y, radius = 12) {
    const h = this.handles;
    if (!h) return -1;
    return this.#pick(h.pos, h.count, h.interior, h.tol, x, y, radius);
  }

  // The nearest point within `radius` CSS pixels of (x, y) that is not behind the drawn surface
  // (by more than tol), or -1. Interior points pass when drawn over the surface (xray).
  #pick(pos, count, interior, tol, x, y, radius) {
    const r = this.canvas.getBoundingClientRect();
    this.camera.updateMatrixWorld();
    const m = new THREE.Matrix4().multiplyMatrices(this.camera.projectionMatrix, this.camera.matrixWorldInverse).elements;
    const cand = [];
    const r2 = radius * radius, W = r.width / 2, H = r.height / 2;
    for (let i = 0; i < count; i++) {
      const px = pos[3 * i], py = pos[3 * i + 1], pz = pos[3 * i + 2];
      const w = m[3] * px + m[7] * py + m[11] * pz + m[15];
      if (w <= 0) continue;
      const sx = ((m[0] * px + m[4] * py + m[8] * pz + m[12]) / w + 1) * W;
      const sy = (1 - (m[1] * px + m[5] * py + m[9] * pz + m[13]) / w) * H;
      const d = (sx - x) ** 2 + (sy - y) ** 2;
      if (d >= r2) continue;
      cand.push({ i, d });
    }
    if (!cand.length) return -1;
    cand.sort((a, b) => a.d - b.d);
    const q = new THREE.Vector3();
    for (const c of cand.slice(0, 16)) {
      if (this.xray && interior?.[c.i]) return c.i;
      if (!this.#occluded(q.fromArray(pos, 3 * c.i), tol)) return c.i;
    }
    return -1;
  }

  // Whether the drawn surface (solid boundary, surfaces, slice; the cut-away half excepted)
  // crosses the segment from the camera to p short of p by more than `tol`. On the CPU, one
  // pass over the triangles (a pick only: the GPU is not waited for).
  #occluded(p, tol) {
    const o = this.camera.getWorldPosition(new THREE.Vector3());
    const dx = p.x - o.x, dy = p.y - o.y, dz = p.z - o.z;
    const len = Math.hypot(dx, dy, dz);
    if (len <= tol) return false;
    const ux = dx / len, uy = dy / len, uz = dz / len, tmax = len - tol;
    const cut = this.slicing ? this.clipPlane : null;
    for (const k of ['solids', 'surfaces', 'slice']) {
      const m = this.parts[k];
      if (!m?.isMesh || !m.visible) continue;
      const g = m.geometry, P = g.attributes.position.array, I = g.index?.array;
      const nt = (I ? I.length : P.length / 3) / 3;
      const clip = k !== 'slice' ? cut : null;
      for (let t = 0; t < nt; t++) {
        const a = 3 * (I ? I[3 * t] : 3 * t), b = 3 * (I ? I[3 * t + 1] : 3 * t + 1), c = 3 * (I ? I[3 * t + 2] : 3 * t + 2);
        const e1x = P[b] - P[a], e1y = P[b + 1] - P[a + 1], e1z = P[b + 2] - P[a + 2];
        const e2x = P[c] - P[a], e2y = P[c + 1] - P[a + 1], e2z = P[c + 2] - P[a + 2];
        const px = uy * e2z - uz * e2y, py = uz * e2x - ux * e2z, pz = ux * e2y - uy * e2x;
        const det = e1x * px + e1y * py + e1z * pz;
        if (det > -1e-12 && det < 1e-12) continue;
        const inv = 1 / det;
        const sx = o.x - P[a], sy = o.y - P[a + 1], sz = o.z - P[a + 2];
        const u = (sx * px + sy * py + sz * pz) * inv;
        if (u < 0 || u > 1) continue;
        const qx = sy * e1z - sz * e1y, qy = sz * e1x - sx * e1z, qz = sx * e1y - sy * e1x;
        const v = (ux * qx + uy * qy + uz * qz) * inv;
        if (v < 0 || u + v > 1) continue;
        const d = (e2x * qx + e2y * qy + e2z * qz) * inv;
        if (d <= 0 || d >= tmax) continue;
        if (clip && clip.normal.x * (o.x + d * ux) + clip.normal.y * (o.y + d * uy) + clip.normal.z * (o.z + d * uz) + clip.constant < 0) continue;
        return true;
      }
    }
    return false;
  }

  // ---- the control cage -------------------------------------------------------------------

  // complex: GET /complex (vertices, simplices, classes, tags).
  setCage(complex) {
    this.cageGroup.traverse((o) => { o.geometry?.dispose(); o.material?.dispose(); });
    this.cageGroup.clear();
    const nv = complex.vertices.length;
    const pos = new Float32Array(nv * 3);
    complex.vertices.forEach((v, i) => pos.set(v, 3 * i));
    const vrule = complex.classes.vertices.map((c) => c.rule);
    const edges = complex.classes.edges.map((e) => ({ v: e.vertices, rule: e.rule, singular: e.singular }));
    // every triangle of the complex (posted ones and faces of tetrahedra), for picking surfaces
    const faces = new Map();
    for (const s of complex.simplices) {
      const tri = s.length === 3 ? [s] : s.length === 4 ? [[s[0], s[1], s[2]], [s[0], s[1], s[3]], [s[0], s[2], s[3]], [s[1], s[2], s[3]]] : [];
      for (const t of tri) faces.set([...t].sort((a, b) => a - b).join(','), t);
    }
    // tagged simplices (drawn with a halo): singular ones and those with a sharpness; `sharp`
    // maps each to its sharpness (singular: Infinity) for colouring by sharpness
    const singular = complex.tags?.singular || [];
    const semi = (complex.tags?.sharpness || []).filter((e) => e.value > 0);
    const tags = [...singular, ...semi.map((e) => e.simplex)];
    const sharp = new Map();
    for (const e of semi) sharp.set(simplexKey(e.simplex), Math.fround(e.value) >= 10 ? Infinity : e.value);
    for (const t of singular) sharp.set(simplexKey(t), Infinity);
    this.cage = { pos, vrule, edges, faces: [...faces.values()], tags, sharp };

    // a vertex only in tetrahedra and on none of their boundary triangles is interior
    const interior = new Uint8Array(nv).fill(1), faceCount = new Map();
    for (const s of complex.simplices) {
      if (s.length < 4) for (const v of s) interior[v] = 0;
      else for (const t of [[s[0], s[1], s[2]], [s[0], s[1], s[3]], [s[0], s[2], s[3]], [s[1], s[2], s[3]]]) {
        const k = [...t].sort((a, b) => a - b).join(',');
        faceCount.set(k, (faceCount.get(k) || 0) + 1);
      }
    }
    for (const [k, c] of faceCount) if (c === 1) for (const v of k.split(',')) interior[Number(v)] = 0;
    // the depth tolerance of the handles: half the median edge length
    const lens = edges.map(({ v: [a, b] }) => Math.hypot(pos[3 * a] - pos[3 * b], pos[3 * a + 1] - pos[3 * b + 1], pos[3 * a + 2] - pos[3 * b + 2])).sort((a, b) => a - b);
    this.cage.tol = lens.length ? lens[lens.length >> 1] / 2 : 0.05;
    this.cage.interior = interior;

    const colors = new Float32Array(nv * 3);
    this.cage.colors = colors;
    const posAttr = new THREE.BufferAttribute(pos, 3);
    const colAttr = new THREE.BufferAttribute(colors, 3);
    const pointsOf = (mat) => {
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', posAttr);
      g.setAttribute('color', colAttr);
      const o = new THREE.Points(g, mat);
      o.renderOrder = 10;
      o.frustumCulled = false;
      return o;
    };
    this.cage.points = pointsOf(handleMaterial({ size: 12, vertexColors: true, map: this.disc }, this.cage.tol));
    this.cage.over = pointsOf(handleMaterial({ size: 12, vertexColors: true, map: this.disc, depthTest: false, transparent: true, opacity: 0.7 }, 0));
    this.cage.posAttr = posAttr;
    this.cage.handles = { level: 0, attr: posAttr, pos, count: nv, interior, tol: this.cage.tol, front: this.cage.points, over: this.cage.over };
    // each vertex's ends in the edge segments (slot 2k + e of edge k), for moves in place
    const deg = new Int32Array(nv + 1);
    for (const e of edges) { deg[e.v[0] + 1]++; deg[e.v[1] + 1]++; }
    for (let i = 0; i < nv; i++) deg[i + 1] += deg[i];
    const slots = new Int32Array(2 * edges.length), fill = deg.slice(0, nv);
    edges.forEach((e, k) => { slots[fill[e.v[0]]++] = 2 * k; slots[fill[e.v[1]]++] = 2 * k + 1; });
    this.cage.edgeStart = deg;
    this.cage.edgeSlots = slots;

    const tv = tags.filter((t) => t.length === 1).map((t) => t[0]);
    const tg = new THREE.BufferGeometry();
    tg.setAttribute('position', new THREE.BufferAttribute(pos, 3));
    tg.setIndex(tv);
    this.cage.tagPoints = new THREE.Points(tg, new THREE.PointsMaterial({ size: 20, sizeAttenuation: false, color: TAG, map: this.disc, alphaTest: 0.5, depthTest: false }));
    this.cage.tagPoints.renderOrder = 9;

    const ec = new Float32Array(edges.length * 6);
    this.cage.colAttr = colAttr;
    this.cage.edgeColors = ec;
    this.#fillCageColors();
    this.cage.edgeLines = new LineSegments2(new LineSegmentsGeometry(), new LineMaterial({ linewidth: 2, vertexColors: true }));
    this.cage.edgeLines.frustumCulled = false;
    this.cage.tagLines = new LineSegments2(new LineSegmentsGeometry(), new LineMaterial({ linewidth: 7, color: TAG }));
    this.cage.tagLines.renderOrder = -1;

    const fg = new THREE.BufferGeometry();
    fg.setAttribute('position', new THREE.BufferAttribute(pos, 3));
    fg.setIndex(this.cage.faces.flat());
    this.cage.faceMesh = new THREE.Mesh(fg, new THREE.MeshBasicMaterial({ side: THREE.DoubleSide }));
    this.cage.faceMesh.visible = false; // raycast only
    const tf = tags.filter((t) => t.length === 3).flat();
    const tfg = new THREE.BufferGeometry();
    tfg.setAttribute('position', new THREE.BufferAttribute(pos, 3));
    tfg.setIndex(tf);
    this.cage.tagFaces = new THREE.Mesh(tfg, new THREE.MeshBasicMaterial({ color: 0xffe119, transparent: true, opacity: 0.45, side: THREE.DoubleSide, depthWrite: false }));

    this.#updateCageLines();
    this.cageGroup.add(this.cage.tagLines, this.cage.edgeLines, this.cage.tagPoints, this.cage.points, this.cage.over, this.cage.faceMesh, this.cage.tagFaces);
    if (!this.handles || this.handles.level === 0) this.setHandles(0);
    this.applyVisibility();
    this.render();
  }

  #updateCageLines() {
    const { pos, edges, tags } = this.cage;
    const seg = (list) => {
      const a = new Float32Array(list.length * 6);
      list.forEach(([i, j], k) => { a.set(pos.subarray(3 * i, 3 * i + 3), 6 * k); a.set(pos.subarray(3 * j, 3 * j + 3), 6 * k + 3); });
      return a;
    };
    const eg = new LineSegmentsGeometry().setPositions(seg(edges.map((e) => e.v)));
    eg.setColors(this.cage.edgeColors);
    this.cage.edgeLines.geometry.dispose();
    this.cage.edgeLines.geometry = eg;
    const te = tags.filter((t) => t.length === 2);
    this.cage.tagLines.geometry.dispose();
    this.cage.tagLines.geometry = new LineSegmentsGeometry().setPositions(seg(te));
    this.cage.tagLines.visible = te.length > 0;
  }

  cagePosition(i) {
    return new THREE.Vector3().fromArray(this.cage.pos, 3 * i);
  }

  // Move control vertices in the drawing only (the daemon is told by main.js, or told us): the
  // points and the ends of their edges are written in place.
  moveCageVertex(i, p) {
    this.moveCageVertices([i], [p.x, p.y, p.z]);
  }

  // indices: control vertex indices; xyz: 3 numbers each.
  moveCageVertices(indices, xyz) {
    const c = this.cage, ib = c.edgeLines.geometry.attributes.instanceStart?.data;
    for (let k = 0; k < indices.length; k++) {
      const i = indices[k];
      for (let a = 0; a < 3; a++) c.pos[3 * i + a] = xyz[3 * k + a];
      if (ib) for (let s = c.edgeStart[i]; s < c.edgeStart[i + 1]; s++) ib.array.set(c.pos.subarray(3 * i, 3 * i + 3), 3 * c.edgeSlots[s]);
    }
    if (ib) ib.needsUpdate = true;
    else this.#updateCageLines();
    c.posAttr.needsUpdate = true;
    for (const o of [c.tagPoints, c.faceMesh, c.tagFaces]) {
      o.geometry.attributes.position.needsUpdate = true;
      o.geometry.computeBoundingSphere();
    }
    if (c.tags.some((t) => t.length === 2)) {
      const te = c.tags.filter((t) => t.length === 2);
      const a = new Float32Array(te.length * 6);
      te.forEach(([i, j], k) => { a.set(c.pos.subarray(3 * i, 3 * i + 3), 6 * k); a.set(c.pos.subarray(3 * j, 3 * j + 3), 6 * k + 3); });
      c.tagLines.geometry.dispose();
      c.tagLines.geometry = new LineSegmentsGeometry().setPositions(a);
    }
    this.requestRender();
  }

  // ---- picking (screen space, CSS pixels relative to the canvas) --------------------------

  toScreen(p) {
    const v = p.clone().project(this.camera);
    const r = this.canvas.getBoundingClientRect();
    return { x: (v.x + 1) / 2 * r.width, y: (1 - v.y) / 2 * r.height, behind: v.z > 1 };
  }

  // The control vertex under (x, y), not behind the surface (see #pick), or -1.
  vertexAt(x, y, radius = 12) {
    if (!this.cage) return -1;
    const c = this.cage;
    return this.#pick(c.pos, c.pos.length / 3, c.interior, c.tol, x, y, radius);
  }

  // The control edge under (x, y), or null: the nearest within `radius` whose point under the
  // pointer is not behind the drawn surface (by more than the handles' tolerance, as #pick).
  edgeAt(x, y, radius = 7) {
    if (!this.cage) return null;
    const cand = [];
    for (const e of this.cage.edges) {
      const a = this.toScreen(this.cagePosition(e.v[0])), b = this.toScreen(this.cagePosition(e.v[1]));
      if (a.behind || b.behind) continue;
      const dx = b.x - a.x, dy = b.y - a.y, L = dx * dx + dy * dy;
      const t = L ? Math.max(0, Math.min(1, ((x - a.x) * dx + (y - a.y) * dy) / L)) : 0;
      const d = Math.hypot(a.x + t * dx - x, a.y + t * dy - y);
      if (d < radius) cand.push({ v: e.v, d });
    }
    if (!cand.length) return null;
    cand.sort((p, q) => p.d - q.d);
    const r = this.canvas.getBoundingClientRect();
    const ray = new THREE.Raycaster();
    ray.setFromCamera(new THREE.Vector2((x / r.width) * 2 - 1, -(y / r.height) * 2 + 1), this.camera);
    const on = new THREE.Vector3();
    for (const c of cand.slice(0, 16)) {
      // the edge's point nearest the line of sight through the pointer
      ray.ray.distanceSqToSegment(this.cagePosition(c.v[0]), this.cagePosition(c.v[1]), undefined, on);
      if (!this.#occluded(on, this.cage.tol)) return c.v;
    }
    return null;
  }

  // The control triangle under (x, y), or null: the nearest the line of sight meets outside the
  // cross-section's cut-away half, so with the cut on a click on it reaches the triangles inside
  // a solid (an embedded surface's), not only the cage's outer ones.
  faceAt(x, y) {
    if (!this.cage) return null;
    const r = this.canvas.getBoundingClientRect();
    const ray = new THREE.Raycaster();
    ray.setFromCamera(new THREE.Vector2((x / r.width) * 2 - 1, -(y / r.height) * 2 + 1), this.camera);
    const cut = this.slicing ? this.clipPlane : null, eps = 1e-3 * this.cage.tol;
    const hit = ray.intersectObject(this.cage.faceMesh, false)
      .find((h) => !cut || cut.distanceToPoint(h.point) >= -eps);
    return hit ? this.cage.faces[hit.faceIndex] : null;
  }

  // The point under (x, y) on the plane through `through` facing the camera (for dragging).
  pointOnViewPlane(x, y, through) {
    const r = this.canvas.getBoundingClientRect();
    const ray = new THREE.Raycaster();
    ray.setFromCamera(new THREE.Vector2((x / r.width) * 2 - 1, -(y / r.height) * 2 + 1), this.camera);
    const n = this.camera.getWorldDirection(new THREE.Vector3());
    const plane = new THREE.Plane().setFromNormalAndCoplanarPoint(n, through);
    return ray.ray.intersectPlane(plane, new THREE.Vector3());
  }

  // Render and read back the frame: how many pixels are not background, and a coarse 16 × 16
  // signature of the picture (for tests: "something is drawn", "the shape changed").
  pixelStats() {
    this.render();
    const gl = this.renderer.getContext();
    const w = gl.drawingBufferWidth, h = gl.drawingBufferHeight;
    const px = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    const br = (BACKGROUND >> 16) & 255, bgG = (BACKGROUND >> 8) & 255, bb = BACKGROUND & 255;
    const sig = new Float64Array(256), cnt = new Float64Array(256);
    let fg = 0;
    for (let y = 0; y < h; y++)
      for (let x = 0; x < w; x++) {
        const k = 4 * (y * w + x);
        const diff = Math.abs(px[k] - br) + Math.abs(px[k + 1] - bgG) + Math.abs(px[k + 2] - bb);
        if (diff > 30) fg++;
        const cell = Math.floor((16 * y) / h) * 16 + Math.floor((16 * x) / w);
        sig[cell] += px[k] + px[k + 1] + px[k + 2];
        cnt[cell] += 3;
      }
    return { width: w, height: h, foreground: fg, signature: Array.from(sig, (s, i) => Math.round(s / cnt[i])) };
  }
}
