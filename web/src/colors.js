// Colours: one per rule family (the `rule` names of GET /complex and the `_RULE` ids of the GLB,
// docs/OUTPUTS.md), and the viridis map the daemon applies with `colormap=` (api/out.c).
import * as THREE from 'three';

// Rule id (as in `_RULE`) -> name, in the daemon's order (core/sd.h sd_rule).
export const RULE_NAMES = ['corner', 'curve', 'loop', 'loop-boundary', 'solid', 'solid-boundary',
  'N1', 'N2', 'G1', 'G2', 'ying-zorin-crease', 'ying-zorin-corner', 'ying-zorin-petal',
  'ying-zorin-fixed-disk', 'ying-zorin-dart', 'ying-zorin-concave'];

// sRGB hex per family; rules the daemon may add later (e.g. "ying-zorin-…") fall back by prefix.
const RULE_HEX = {
  corner: '#e6194b',
  curve: '#f58231',
  loop: '#3cb44b',
  'loop-boundary': '#bfef45',
  solid: '#4363d8',
  'solid-boundary': '#42d4f4',
  N1: '#911eb4',
  N2: '#f032e6',
  G1: '#ffe119',
  G2: '#fabed4',
  'ying-zorin': '#469990',
  unknown: '#808080',
};

export const RULE_DESCRIPTIONS = {
  corner: 'fixed point (0-mask)',
  curve: 'cubic B-spline along a curve or crease',
  loop: 'Loop surface',
  'loop-boundary': 'B-spline along a surface boundary',
  solid: 'box-spline solid',
  'solid-boundary': 'Loop on the solid boundary',
  N1: 'non-manifold: follows one dimension',
  N2: 'non-manifold: follows one pair',
  G1: 'non-manifold: singular (kept)',
  G2: 'non-manifold: 3-simplex stencil (default)',
  'ying-zorin': 'Ying–Zorin non-manifold surface',
};

export function ruleFamily(name) {
  if (name in RULE_HEX) return name;
  if (typeof name === 'string' && name.startsWith('ying-zorin')) return 'ying-zorin';
  return 'unknown';
}

export function ruleHex(name) {
  return RULE_HEX[ruleFamily(name)];
}

const ruleColors = new Map();
// A THREE.Color (linear working space) for a rule name or id; shared, do not modify.
export function ruleColor(nameOrId) {
  const name = typeof nameOrId === 'number' ? (RULE_NAMES[nameOrId] ?? 'unknown') : nameOrId;
  const fam = ruleFamily(name);
  if (!ruleColors.has(fam)) ruleColors.set(fam, new THREE.Color(RULE_HEX[fam]));
  return ruleColors.get(fam);
}

// Viridis sampled at t = 0, 1/8, ..., 1 (sRGB), exactly the daemon's table.
export const VIRIDIS = [
  [0.267004, 0.004874, 0.329415], [0.278826, 0.175490, 0.483397],
  [0.229739, 0.322361, 0.545706], [0.172719, 0.448791, 0.557885],
  [0.127568, 0.566949, 0.550556], [0.157851, 0.683765, 0.501686],
  [0.369214, 0.788888, 0.382914], [0.678489, 0.863742, 0.189503],
  [0.993248, 0.906157, 0.143936],
];

export function viridisCss() {
  const stops = VIRIDIS.map(([r, g, b], i) =>
    `rgb(${Math.round(r * 255)} ${Math.round(g * 255)} ${Math.round(b * 255)}) ${(i * 12.5).toFixed(1)}%`);
  return `linear-gradient(to right, ${stops.join(', ')})`;
}

// Sharpness (PUT /tags "sharpness"; 10 and over, and singular tags, are infinitely sharp): a ramp
// from pale yellow (just above 0) through orange to dark red (10), simplices without any sharpness
// in grey. sRGB stops at s = 0, 2.5, 5, 7.5, 10.
const SHARP_STOPS = [[1.0, 0.93, 0.6], [0.99, 0.7, 0.3], [0.95, 0.42, 0.13], [0.8, 0.15, 0.1], [0.45, 0.0, 0.05]];
export const NO_SHARPNESS = new THREE.Color('#9a9a9a');

// A THREE.Color (linear working space) for a sharpness s > 0 (Infinity allowed).
export function sharpnessColor(s) {
  const t = Math.min(Math.max(s, 0), 10) / 2.5;
  const i = Math.min(Math.floor(t), SHARP_STOPS.length - 2), f = t - i;
  const a = SHARP_STOPS[i], b = SHARP_STOPS[i + 1];
  return new THREE.Color().setRGB(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]), THREE.SRGBColorSpace);
}

export function sharpnessCss() {
  const stops = SHARP_STOPS.map(([r, g, b], i) =>
    `rgb(${Math.round(r * 255)} ${Math.round(g * 255)} ${Math.round(b * 255)}) ${i * 25}%`);
  return `linear-gradient(to right, ${stops.join(', ')})`;
}
