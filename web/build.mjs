// Builds the web front end: node web/build.mjs OUTDIR (the Makefile passes build/web).
//
// esbuild bundles src/main.js (three.js and the app) and its CSS into OUTDIR/assets/ with
// content hashes in their names; index.html is written with those names filled in; and
// OUTDIR/assets.list tells tools/embed.c what to embed into the daemon, one
// URLPATH|CONTENT_TYPE|CACHE_CONTROL|FILE a line: index.html is revalidated (no-cache, ETag), the
// hashed bundles are immutable. OUTDIR is emptied first so no stale bundle is embedded.
import * as esbuild from 'esbuild';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const out = path.resolve(process.argv[2] || path.join(here, '..', 'build', 'web'));
fs.rmSync(out, { recursive: true, force: true });
fs.mkdirSync(out, { recursive: true });

const result = await esbuild.build({
  entryPoints: [path.join(here, 'src', 'main.js')],
  bundle: true,
  format: 'esm',
  target: ['es2020'],
  minify: true,
  legalComments: 'none',
  entryNames: 'assets/app-[hash]',
  outdir: out,
  metafile: true,
  logLevel: 'warning',
});

const files = Object.keys(result.metafile.outputs).map((f) => path.resolve(f));
const js = files.find((f) => f.endsWith('.js'));
const css = files.find((f) => f.endsWith('.css'));
if (!js || !css) throw new Error(`esbuild wrote ${files.join(', ')}: expected one .js and one .css`);
const url = (f) => '/' + path.relative(out, f).split(path.sep).join('/');

const template = fs.readFileSync(path.join(here, 'index.html'), 'utf8');
if (!template.includes('%APP_JS%') || !template.includes('%APP_CSS%'))
  throw new Error('web/index.html must contain %APP_JS% and %APP_CSS%');
const html = template.replaceAll('%APP_JS%', url(js)).replaceAll('%APP_CSS%', url(css));
fs.writeFileSync(path.join(out, 'index.html'), html);

const immutable = 'public,max-age=31536000,immutable';
const rel = (f) => path.relative(process.cwd(), f); // embed runs where make does
const list = [
  `/|text/html;charset=utf-8|no-cache|${rel(path.join(out, 'index.html'))}`,
  `${url(js)}|text/javascript;charset=utf-8|${immutable}|${rel(js)}`,
  `${url(css)}|text/css;charset=utf-8|${immutable}|${rel(css)}`,
];
for (const line of list)
  if (/\s/.test(line)) throw new Error(`asset spec with white space (the Makefile splits on it): ${line}`);
fs.writeFileSync(path.join(out, 'assets.list'), list.join('\n') + '\n');
const kb = (f) => (fs.statSync(f).size / 1024).toFixed(0) + ' KiB';
console.log(`web: ${url(js)} ${kb(js)}, ${url(css)} ${kb(css)}`);
