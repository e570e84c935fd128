// The vendored zstd decoder (vendor/fzstd.mjs, MIT, licence beside it) is the ES module build
// of the npm package pinned in package.json and package-lock.json, byte for byte.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const web = path.join(path.dirname(fileURLToPath(import.meta.url)), '..');
const pkg = path.join(web, 'node_modules/fzstd');
const missing = !fs.existsSync(pkg);
if (missing && process.env.CI === 'true') throw new Error(`${pkg} is missing: npm ci in web/ (.ci/run does)`);

test('vendor/fzstd.mjs is the pinned npm package\'s esm/index.mjs', { skip: missing && 'npm ci in web/ first' }, () => {
  const lock = JSON.parse(fs.readFileSync(path.join(web, 'package-lock.json'), 'utf8'));
  const pinned = JSON.parse(fs.readFileSync(path.join(web, 'package.json'), 'utf8')).dependencies.fzstd;
  const installed = JSON.parse(fs.readFileSync(path.join(pkg, 'package.json'), 'utf8')).version;
  assert.equal(lock.packages['node_modules/fzstd'].version, pinned);
  assert.equal(installed, pinned);
  assert.ok(fs.readFileSync(path.join(web, 'vendor/fzstd.mjs')).equals(fs.readFileSync(path.join(pkg, 'esm/index.mjs'))));
  assert.ok(fs.readFileSync(path.join(web, 'vendor/fzstd.LICENSE')).equals(fs.readFileSync(path.join(pkg, 'LICENSE'))));
});
