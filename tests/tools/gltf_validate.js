// gltf_validate.js — run the Khronos glTF-Validator on each file given; print one summary line
// per file (and every message) and exit 1 if any file has an error or a warning.
// usage: node tests/tools/gltf_validate.js FILE.glb|FILE.gltf ...
'use strict';
const fs = require('fs');
const path = require('path');
const validator = require('gltf-validator');

async function check(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    maxIssues: 0,
    writeTimestamp: false,
    format: file.endsWith('.glb') ? 'glb' : 'gltf',
    uri: path.basename(file),
  });
  const i = report.issues;
  console.log(`${file}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos, ` +
              `${i.numHints} hints; ${report.info ? report.info.totalVertexCount : '?'} vertices, ` +
              `${report.info ? report.info.drawCallCount : '?'} draw calls`);
  for (const m of i.messages) {
    if (m.severity <= 1) console.log(`  ${['error', 'warning'][m.severity]} ${m.code} at ${m.pointer}: ${m.message}`);
  }
  return i.numErrors === 0 && i.numWarnings === 0;
}

(async () => {
  let ok = true;
  for (const f of process.argv.slice(2)) ok = (await check(f)) && ok;
  process.exit(ok ? 0 : 1);
})().catch((e) => { console.error(e); process.exit(2); });
