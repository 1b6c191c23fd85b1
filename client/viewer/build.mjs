// Bundles the viewer: src/main.js (three.js and the JS client included) -> OUTDIR/viewer.js,
// minified with a sourcemap, plus index.html and viewer.css. One module and one stylesheet,
// because lucentd's Content-Security-Policy allows only the page's own scripts and styles.
//   node client/viewer/build.mjs [--outdir DIR] [--no-minify]
import { build } from 'esbuild';
import { copyFileSync, mkdirSync, readFileSync, statSync, writeFileSync } from 'node:fs';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { gzipSync } from 'node:zlib';

const here = dirname(fileURLToPath(import.meta.url));
const args = process.argv.slice(2);
let outdir = resolve(here, '../../build/share/lucent/www'); // the default build tree's web root
let minify = true;
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--outdir' && i + 1 < args.length) outdir = resolve(args[++i]);
  else if (args[i] === '--no-minify') minify = false;
  else {
    console.error(`build.mjs: unknown argument ${args[i]} (usage: build.mjs [--outdir DIR] [--no-minify])`);
    process.exit(2);
  }
}

mkdirSync(outdir, { recursive: true });
const result = await build({
  entryPoints: [join(here, 'src/main.js')],
  outfile: join(outdir, 'viewer.js'),
  bundle: true,
  format: 'esm',
  minify,
  sourcemap: true,
  target: ['es2022'],
  legalComments: 'linked',
  logLevel: 'warning',
  metafile: true,
});
copyFileSync(join(here, 'index.html'), join(outdir, 'index.html'));
copyFileSync(join(here, 'viewer.css'), join(outdir, 'viewer.css'));
const js = readFileSync(join(outdir, 'viewer.js'));
console.log(`viewer: ${join(outdir, 'viewer.js')} ${statSync(join(outdir, 'viewer.js')).size} bytes ` +
  `(${gzipSync(js, { level: 9 }).length} gzip)`);
