// Opens a 3D Tiles tileset in headless Chromium with three.js + 3d-tiles-renderer
// (tiles-page/index.html) from a loopback HTTP server and saves a screenshot.
// Usage: node tests/node/tiles-check.js TILESET_DIR SHOT_JSON OUT.png
// Prints {"loaded": [...content URIs...], "errors": [...], ...} as JSON on stdout.
// CHROMIUM names the browser (default /usr/bin/chromium).
'use strict';
const fs = require('fs');
const http = require('http');
const os = require('os');
const path = require('path');
const puppeteer = require('puppeteer-core');

const [tilesDir, shotJson, outPng] = process.argv.slice(2);
const here = __dirname;
const types = { '.html': 'text/html', '.js': 'text/javascript', '.json': 'application/json', '.glb': 'model/gltf-binary' };

// static files: /tiles/... from the tileset, the page and /node_modules/... from here
function resolve(url) {
  const p = decodeURIComponent(new URL(url, 'http://x').pathname);
  if (p.includes('..')) return null;
  if (p.startsWith('/tiles/')) return path.join(tilesDir, p.slice('/tiles/'.length));
  if (p === '/' || p === '/index.html') return path.join(here, 'tiles-page/index.html');
  if (p.startsWith('/node_modules/')) return path.join(here, p);
  return null;
}

const server = http.createServer((req, res) => {
  const f = resolve(req.url);
  if (!f || !fs.existsSync(f) || !fs.statSync(f).isFile()) {
    res.writeHead(404);
    res.end();
    return;
  }
  res.writeHead(200, { 'Content-Type': types[path.extname(f)] || 'application/octet-stream' });
  fs.createReadStream(f).pipe(res);
});

async function main() {
  await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
  const port = server.address().port;
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'voxlod-chromium-'));
  const shot = JSON.parse(shotJson);
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: [
      '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
      `--user-data-dir=${profile}`, '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
      `--window-size=${shot.width},${shot.height}`,
    ],
  });
  try {
    const page = await browser.newPage();
    const logs = [];
    page.on('console', (m) => logs.push(m.text()));
    page.on('pageerror', (e) => logs.push(String(e)));
    await page.setViewport({ width: shot.width, height: shot.height, deviceScaleFactor: 1 });
    await page.goto(`http://127.0.0.1:${port}/?shot=${encodeURIComponent(shotJson)}`);
    try {
      await page.waitForFunction('window.result !== undefined', { timeout: 120000, polling: 200 });
    } catch (e) {
      throw new Error(`the page did not finish: ${e.message}; its console: ${JSON.stringify(logs)}`);
    }
    const result = await page.evaluate('window.result');
    const canvas = await page.$('canvas');
    await canvas.screenshot({ path: outPng });
    result.logs = logs;
    process.stdout.write(JSON.stringify(result));
  } finally {
    await browser.close();
    server.close();
    fs.rmSync(profile, { recursive: true, force: true });
  }
}

main().catch((e) => {
  console.error(`tiles-check: ${e.stack || e}`);
  process.exit(2);
});
