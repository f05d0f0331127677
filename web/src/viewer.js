// The three.js view: one subdivided level (the GLB the daemon streams), the control cage (the
// posted complex, from GET /complex) on top of it, an optional cross-section plane, and the
// screen-space picking the tools need. It knows nothing of HTTP; main.js feeds it.
//
// Level GLB layout (docs/OUTPUTS.md): primitives in the order points, curves, surfaces, solids,
// slice, empty ones left out. POINTS and LINES are unambiguous; of the indexed TRIANGLES ones the
// first is the surfaces when the level has surface triangles (its stats), the other the solid
// boundary; the non-indexed TRIANGLES one without `_RULE` is the slice.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { LineSegments2 } from 'three/addons/lines/LineSegments2.js';
import { LineSegmentsGeometry } from 'three/addons/lines/LineSegmentsGeometry.js';
import { LineMaterial } from 'three/addons/lines/LineMaterial.js';
import { ruleColor } from './colors.js';

export const BACKGROUND = 0x1e2229;
const PLAIN = { points: 0xffffff, curves: 0xffa94d, surfaces: 0xc9d6c4, solids: 0xb8c7e0 };
const SLICE = 0xff8c42;
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

// COLOR_0 holds matplotlib's (sRGB) viridis values; convert so the screen shows viridis.
function colorsFromSrgb(attr) {
  const out = new Float32Array(attr.count * 3);
  const c = new THREE.Color();
  for (let i = 0; i < attr.count; i++) {
    c.setRGB(attr.getX(i), attr.getY(i), attr.getZ(i), THREE.SRGBColorSpace);
    c.toArray(out, 3 * i);
  }
  return new THREE.BufferAttribute(out, 3);
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
    this.controls.addEventListener('change', () => {
      this.#orientClip();
      this.render();
    });

    this.levelGroup = new THREE.Group();
    this.cageGroup = new THREE.Group();
    this.scene.add(this.levelGroup, this.cageGroup);
    this.parts = {}; // points, curves, surfaces, solids, slice -> Object3D
    this.visible = { cage: true, points: true, curves: true, surfaces: true, solids: true };
    this.colorMode = 'rule';
    this.clipPlane = new THREE.Plane(new THREE.Vector3(0, 0, -1), 0);
    this.slicing = false;
    this.disc = discTexture();
    this.planeHelper = null;
    this.cage = null;

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
    this.renderer.render(this.scene, this.camera);
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
    gltf.scene.traverse((o) => { if (o.isMesh || o.isPoints || o.isLine) prims.push(o); });
    const tris = prims.filter((o) => o.isMesh && o.geometry.index);
    const surfacesFirst = (stats?.counts?.triangles ?? 0) > 0;
    for (const o of prims) {
      const g = o.geometry;
      let part;
      if (o.isPoints) part = 'points';
      else if (o.isLine) part = 'curves';
      else if (!g.index && !g.attributes._rule) part = 'slice';
      else part = tris.length === 2 ? (o === tris[0] ? 'surfaces' : 'solids') : (surfacesFirst ? 'surfaces' : 'solids');
      this.parts[part] = this.#makePart(part, g);
      o.material?.dispose();
    }
    for (const o of Object.values(this.parts)) this.levelGroup.add(o);
    this.applyColors();
    this.applyVisibility();
    this.applyClipping();
    this.render();
  }

  #makePart(part, g) {
    g.userData.ruleColors = g.attributes._rule ? colorsFromRules(g.attributes._rule) : null;
    g.userData.attrColors = g.attributes.color ? colorsFromSrgb(g.attributes.color) : null;
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
  }

  applyColors() {
    for (const [part, o] of Object.entries(this.parts)) {
      if (part === 'slice') continue;
      const g = o.userData.source || o.geometry;
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
    const tags = complex.tags?.singular || [];
    this.cage = { pos, vrule, edges, faces: [...faces.values()], tags };

    const colors = new Float32Array(nv * 3);
    vrule.forEach((r, i) => ruleColor(r).toArray(colors, 3 * i));
    const vg = new THREE.BufferGeometry();
    vg.setAttribute('position', new THREE.BufferAttribute(pos, 3));
    vg.setAttribute('color', new THREE.BufferAttribute(colors, 3));
    const vm = new THREE.PointsMaterial({ size: 12, sizeAttenuation: false, vertexColors: true, map: this.disc, alphaTest: 0.5, depthTest: false });
    this.cage.points = new THREE.Points(vg, vm);
    this.cage.points.renderOrder = 10;

    const tv = tags.filter((t) => t.length === 1).map((t) => t[0]);
    const tg = new THREE.BufferGeometry();
    tg.setAttribute('position', new THREE.BufferAttribute(pos, 3));
    tg.setIndex(tv);
    this.cage.tagPoints = new THREE.Points(tg, new THREE.PointsMaterial({ size: 20, sizeAttenuation: false, color: TAG, map: this.disc, alphaTest: 0.5, depthTest: false }));
    this.cage.tagPoints.renderOrder = 9;

    const ec = new Float32Array(edges.length * 6);
    edges.forEach((e, k) => { const c = ruleColor(e.rule); c.toArray(ec, 6 * k); c.toArray(ec, 6 * k + 3); });
    this.cage.edgeLines = new LineSegments2(new LineSegmentsGeometry(), new LineMaterial({ linewidth: 2, vertexColors: true }));
    this.cage.edgeColors = ec;
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
    this.cageGroup.add(this.cage.tagLines, this.cage.edgeLines, this.cage.tagPoints, this.cage.points, this.cage.faceMesh, this.cage.tagFaces);
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

  // Move control vertex i in the drawing only (the daemon is told by main.js).
  moveCageVertex(i, p) {
    this.cage.pos.set([p.x, p.y, p.z], 3 * i);
    for (const o of [this.cage.points, this.cage.tagPoints, this.cage.faceMesh, this.cage.tagFaces]) {
      o.geometry.attributes.position.needsUpdate = true;
      o.geometry.computeBoundingSphere();
    }
    this.#updateCageLines();
    this.render();
  }

  // ---- picking (screen space, CSS pixels relative to the canvas) --------------------------

  toScreen(p) {
    const v = p.clone().project(this.camera);
    const r = this.canvas.getBoundingClientRect();
    return { x: (v.x + 1) / 2 * r.width, y: (1 - v.y) / 2 * r.height, behind: v.z > 1 };
  }

  vertexAt(x, y, radius = 12) {
    if (!this.cage) return -1;
    let best = -1, bd = radius * radius;
    const n = this.cage.pos.length / 3;
    for (let i = 0; i < n; i++) {
      const s = this.toScreen(this.cagePosition(i));
      const d = (s.x - x) ** 2 + (s.y - y) ** 2;
      if (!s.behind && d < bd) { bd = d; best = i; }
    }
    return best;
  }

  edgeAt(x, y, radius = 7) {
    if (!this.cage) return null;
    let best = null, bd = radius;
    for (const e of this.cage.edges) {
      const a = this.toScreen(this.cagePosition(e.v[0])), b = this.toScreen(this.cagePosition(e.v[1]));
      if (a.behind || b.behind) continue;
      const dx = b.x - a.x, dy = b.y - a.y, L = dx * dx + dy * dy;
      const t = L ? Math.max(0, Math.min(1, ((x - a.x) * dx + (y - a.y) * dy) / L)) : 0;
      const d = Math.hypot(a.x + t * dx - x, a.y + t * dy - y);
      if (d < bd) { bd = d; best = e.v; }
    }
    return best;
  }

  faceAt(x, y) {
    if (!this.cage) return null;
    const r = this.canvas.getBoundingClientRect();
    const ray = new THREE.Raycaster();
    ray.setFromCamera(new THREE.Vector2((x / r.width) * 2 - 1, -(y / r.height) * 2 + 1), this.camera);
    const hit = ray.intersectObject(this.cage.faceMesh, false)[0];
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
