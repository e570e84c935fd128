// Opens the voxlod web viewer (web/index.html) in headless Chromium, waits until
// `window.voxlodStatus.complete` (every node the camera wants is resident and drawn), saves a
// screenshot of the canvas and prints the status as JSON on stdout.
//
// Usage:
//   node tests/node/web-check.js --url URL OUT.png
//       a viewer already served (e.g. by `voxlod serve`); URL with its parameters
//   node tests/node/web-check.js --static WEB_DIR FILE QUERY OUT.png
//       serves WEB_DIR (the viewer) and FILE (as /data/NAME) with serve-static, a plain static
//       server with range support, counts the bytes of FILE it sends, and opens
//       /index.html?file=data/NAME&QUERY
//   node tests/node/web-check.js --static-no-ranges WEB_DIR FILE QUERY OUT.png
//       the same from a server that ignores Range headers (the viewer must say so)
// INTERACT=1: after the picture, orbit, zoom out and pan with the mouse, each followed by a
// complete frame; the cameras in `interactions`.
// CHROMIUM names the browser (default /usr/bin/chromium); TIMEOUT_MS the wait (default 90000).
// The JSON: the page's voxlodStatus, `logs` (its console) and, with --static,
// `server_bytes` (bytes of FILE sent) and `server_requests`.
'use strict';
const fs = require('fs');
const http = require('http');
const os = require('os');
const path = require('path');
const puppeteer = require('puppeteer-core');
const serveStatic = require('serve-static');

async function staticServer(webDir, file, ranges) {
  const name = path.basename(file);
  const viewer = serveStatic(webDir, { index: ['index.html'] });
  const data = serveStatic(path.dirname(file), { index: false, acceptRanges: ranges });
  const counted = { bytes: 0, requests: 0 };
  const server = http.createServer((req, res) => {
    const done = () => {
      res.statusCode = 404;
      res.end();
    };
    if (req.url.startsWith('/data/')) {
      if (decodeURIComponent(req.url.slice(6).split('?')[0]) !== name) return done();
      counted.requests++;
      const write = res.write.bind(res);
      const end = res.end.bind(res);
      res.write = (chunk, ...a) => {
        if (chunk) counted.bytes += chunk.length;
        return write(chunk, ...a);
      };
      res.end = (chunk, ...a) => {
        if (chunk && typeof chunk !== 'function') counted.bytes += chunk.length;
        return end(chunk, ...a);
      };
      req.url = req.url.slice(5);
      return data(req, res, done);
    }
    return viewer(req, res, done);
  });
  await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
  return { server, counted, base: `http://127.0.0.1:${server.address().port}`, name };
}

async function main() {
  const args = process.argv.slice(2);
  let url;
  let out;
  let local = null;
  if (args[0] === '--url') {
    [, url, out] = args;
  } else if (args[0] === '--static' || args[0] === '--static-no-ranges') {
    const [, webDir, file, query] = args;
    out = args[4];
    local = await staticServer(webDir, file, args[0] === '--static');
    url = `${local.base}/index.html?file=data/${encodeURIComponent(local.name)}&${query}`;
  } else {
    throw new Error('usage: web-check.js --url URL OUT.png | --static[-no-ranges] WEB_DIR FILE QUERY OUT.png');
  }
  const size = /[?&]size=(\d+)x(\d+)/.exec(url);
  const [width, height] = size ? [Number(size[1]), Number(size[2])] : [800, 600];
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'voxlod-chromium-'));
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: [
      '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
      `--user-data-dir=${profile}`, '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
      `--window-size=${width},${height}`,
    ],
  });
  try {
    const page = await browser.newPage();
    const logs = [];
    page.on('console', (m) => logs.push(m.text()));
    // an exception in the page (a syntax error in a module) ends the wait at once
    page.on('pageerror', (e) => {
      logs.push(String(e));
      page.evaluate((m) => { window.voxlodStatus = { error: m }; }, String(e)).catch(() => {});
    });
    await page.setViewport({ width, height, deviceScaleFactor: 1 });
    const t0 = Date.now();
    await page.goto(url);
    try {
      await page.waitForFunction(
        'window.voxlodStatus && (window.voxlodStatus.complete || window.voxlodStatus.error)',
        { timeout: Number(process.env.TIMEOUT_MS || 90000), polling: 100 },
      );
    } catch (e) {
      const s = await page.evaluate('window.voxlodStatus').catch(() => null);
      throw new Error(`the viewer did not complete: ${e.message}; status ${JSON.stringify(s)}; console ${JSON.stringify(logs)}`);
    }
    const status = await page.evaluate('window.voxlodStatus');
    status.wallMs = Date.now() - t0;
    // the canvas's own pixels (the overlay is a separate element, not in them)
    const png = await page.evaluate("document.getElementById('view').toDataURL('image/png')");
    fs.writeFileSync(out, Buffer.from(png.slice(png.indexOf(',') + 1), 'base64'));
    // INTERACT=1: after the picture, the mouse
    if (process.env.INTERACT === '1') {
      // orbit (left drag), then zoom (wheel), then pan (right drag): each changes the camera
      // and leads to another complete frame
      const box = await (await page.$('canvas')).boundingBox();
      const cx = box.x + box.width / 2;
      const cy = box.y + box.height / 2;
      status.interactions = [];
      const settle = async () => {
        await page.waitForFunction('window.voxlodStatus.complete === false', { timeout: 10000, polling: 20 }).catch(() => {});
        await page.waitForFunction('window.voxlodStatus.complete || window.voxlodStatus.error', { timeout: 90000, polling: 100 });
        status.interactions.push(await page.evaluate('window.voxlodStatus.camera'));
      };
      await page.mouse.move(cx, cy);
      await page.mouse.down();
      await page.mouse.move(cx + 60, cy + 20, { steps: 4 });
      await page.mouse.up();
      await settle();
      await page.mouse.wheel({ deltaY: 400 });
      await settle();
      await page.mouse.move(cx, cy);
      await page.mouse.down({ button: 'right' });
      await page.mouse.move(cx + 40, cy, { steps: 4 });
      await page.mouse.up({ button: 'right' });
      await settle();
      status.afterInteraction = await page.evaluate('window.voxlodStatus');
    }
    status.logs = logs;
    if (local) {
      status.server_bytes = local.counted.bytes;
      status.server_requests = local.counted.requests;
    }
    process.stdout.write(JSON.stringify(status));
  } finally {
    await browser.close();
    if (local) local.server.close();
    fs.rmSync(profile, { recursive: true, force: true });
  }
}

main().catch((e) => {
  console.error(`web-check: ${e.stack || e}`);
  process.exit(2);
});
