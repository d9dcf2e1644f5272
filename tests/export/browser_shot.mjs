// Opens a glTF in a real browser: serves tests/export/page (three.js from the pinned npm package,
// no CDN) and the file on 127.0.0.1 at a free port, runs headless Chromium on the page once to
// read what the page reports (--dump-dom) and once for a screenshot, then stops the server.
//
//   node browser_shot.mjs CHROMIUM FILE.gltf|FILE.glb OUT.png SECONDS
//
// Prints one JSON line: {"status": the page's report ("ready bones=N renderer=webgl t=S"),
// "png": OUT.png, "png_bytes": its size}. Exit 1 when the browser or the server fails.
import { execFile } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, statSync } from 'node:fs';
import { createServer } from 'node:http';
import { tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const TYPES = { '.html': 'text/html', '.mjs': 'text/javascript', '.js': 'text/javascript' };

function serve(gltfPath) {
  const roots = { '/page/': join(here, 'page'), '/three/': join(here, 'node_modules', 'three') };
  const server = createServer((request, response) => {
    const path = decodeURIComponent(new URL(request.url, 'http://127.0.0.1').pathname);
    let file = null;
    if (path === '/clip.gltf') file = gltfPath;
    for (const [prefix, root] of Object.entries(roots)) {
      if (path.startsWith(prefix)) {
        const relative = normalize(path.slice(prefix.length));
        if (!relative.startsWith('..')) file = join(root, relative);
      }
    }
    try {
      if (file === null) throw new Error('not found');
      const body = readFileSync(file);
      response.writeHead(200, { 'content-type': TYPES[extname(file)] ?? 'application/octet-stream' });
      response.end(body);
    } catch {
      response.writeHead(404);
      response.end();
    }
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

function chromium(binary, args) {
  return new Promise((resolve, reject) => {
    execFile(binary, args, { timeout: 90000, maxBuffer: 16 << 20 }, (error, stdout, stderr) => {
      if (error) reject(new Error(`${binary} failed: ${error.message}\n${stderr}`));
      else resolve(stdout);
    });
  });
}

async function main() {
  const [binary, gltfPath, pngPath, seconds] = process.argv.slice(2);
  if (!binary || !gltfPath || !pngPath || seconds === undefined) {
    throw new Error('usage: browser_shot.mjs CHROMIUM FILE.gltf OUT.png SECONDS');
  }
  const server = await serve(gltfPath);
  const profile = mkdtempSync(join(tmpdir(), 'tempokey-chromium-'));
  try {
    const url = `http://127.0.0.1:${server.address().port}/page/view.html?t=${seconds}`;
    const flags = [
      '--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--no-first-run',
      `--user-data-dir=${profile}`, '--window-size=800,600', '--virtual-time-budget=20000',
    ];
    const dom = await chromium(binary, [...flags, '--dump-dom', url]);
    const status = (dom.match(/<pre id="status">([^<]*)<\/pre>/) ?? [null, 'no status'])[1];
    await chromium(binary, [...flags, `--screenshot=${pngPath}`, url]);
    process.stdout.write(`${JSON.stringify({ status, png: pngPath, png_bytes: statSync(pngPath).size })}\n`);
  } finally {
    server.close();
    rmSync(profile, { recursive: true, force: true });
  }
}

main().catch((error) => {
  process.stderr.write(`browser_shot: ${error.stack || error}\n`);
  process.exit(1);
});
