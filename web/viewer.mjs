// The browser viewer of a voxlod octree: reads the file's header and node index by HTTP range
// requests, then only the nodes the camera needs by screen-space error (the cut of
// `voxlod render --error`), within a memory budget, decoded in Web Workers and drawn with
// WebGL2 from the voxel records (renderer.mjs). URL parameters: docs/VIEWER.md, "In a
// browser". Publishes `window.voxlodStatus` for scripts and tests.

import { VoxlodFile, voxelSizeAt, CHANNEL_SOURCE_TRIANGLES } from './voxlod-reader.mjs';
import { fetchRange } from './fetch-range.mjs';
import {
  defaultView, frameShot, viewProj, columnMajor, CutContext, robustLevel, robustBounds, upFromShape, vec,
} from './camera.mjs';
import { Renderer, lightDirection } from './renderer.mjs';

const started = performance.now();
const status = {
  complete: false, nodes: 0, bytesFetched: 0, frameMs: 0, occluded: 0,
  wanted: 0, resident: 0, residentBytes: 0, requests: 0, levels: [], firstCompleteMs: null, error: null,
};
window.voxlodStatus = status;

const overlay = document.getElementById('overlay');
const canvas = document.getElementById('view');

function showError(e) {
  status.error = String(e && e.message ? e.message : e);
  overlay.textContent = `error: ${status.error}`;
  overlay.classList.add('error');
  console.error(e);
}

// ---------------------------------------------------------------------------------------------
// Parameters: render's camera (view, up, fov, zoom, target, size, error) and the viewer's own.

const params = new URLSearchParams(location.search);

function vec3(name) {
  const s = params.get(name);
  if (s === null) return null;
  const v = s.split(',').map((c) => Number(c.trim()));
  if (v.length !== 3 || !v.every(Number.isFinite)) throw new Error(`${name}=${s} is not x,y,z (three numbers)`);
  return v;
}

function number(name, fallback) {
  const s = params.get(name);
  if (s === null) return fallback;
  const v = Number(s);
  if (!Number.isFinite(v)) throw new Error(`${name}=${s} is not a number`);
  return v;
}

function flag(name, fallback) {
  const s = params.get(name);
  if (s === null) return fallback;
  if (['1', 'true', 'on', 'yes'].includes(s)) return true;
  if (['0', 'false', 'off', 'no'].includes(s)) return false;
  throw new Error(`${name}=${s} is neither 1 nor 0`);
}

function readParams() {
  const p = {};
  p.file = params.get('file');
  if (!p.file) throw new Error('no file: add ?file=URL of a .voxlod file to the address (relative or absolute)');
  p.url = new URL(p.file, location.href).href;
  const size = params.get('size');
  if (size !== null) {
    const m = /^\s*(\d+)\s*[xX]\s*(\d+)\s*$/.exec(size);
    if (!m) throw new Error(`size=${size} is not WIDTHxHEIGHT (e.g. 1024x768)`);
    p.size = [Number(m[1]), Number(m[2])];
  }
  const d = defaultView();
  p.direction = vec3('view') ?? d.direction;
  p.up = vec3('up');
  p.fov = number('fov', d.fovYDeg);
  p.zoom = number('zoom', d.zoom);
  p.target = vec3('target');
  p.error = number('error', 1);
  if (!(p.error > 0)) throw new Error(`error=${p.error} must be a positive number of pixels`);
  const color = params.get('color') ?? 'voxel';
  if (color !== 'voxel' && color !== 'material') throw new Error(`color=${color} is neither voxel nor material`);
  p.material = color === 'material';
  p.source = flag('source', true);
  p.occlusion = flag('occlusion', true);
  const sides = params.get('sides') ?? '2';
  if (sides !== '1' && sides !== '2') throw new Error(`sides=${sides} is neither 1 nor 2`);
  p.twoSided = sides === '2';
  p.progressive = flag('progressive', true);
  p.budget = number('budget', 256) * 1024 * 1024;
  p.workers = Math.max(1, Math.min(8, number('workers', 2)));
  return p;
}

// ---------------------------------------------------------------------------------------------
// Workers: fetch and decode node payloads.

class Pool {
  constructor(n) {
    this.workers = Array.from({ length: n }, () => new Worker(new URL('./worker.mjs', import.meta.url), { type: 'module' }));
    this.pending = new Map();
    this.next = 0;
    this.turn = 0;
    for (const w of this.workers) {
      w.onmessage = (ev) => {
        const p = this.pending.get(ev.data.id);
        this.pending.delete(ev.data.id);
        p(ev.data);
      };
    }
  }

  run(msg) {
    const id = this.next++;
    const w = this.workers[this.turn++ % this.workers.length];
    return new Promise((resolve) => {
      this.pending.set(id, resolve);
      w.postMessage({ ...msg, id });
    });
  }
}

// ---------------------------------------------------------------------------------------------

async function main() {
  const p = readParams();
  const readRange = async (offset, length) => {
    const { bytes, fetched } = await fetchRange(p.url, offset, length);
    status.bytesFetched += fetched;
    return bytes;
  };
  const file = await VoxlodFile.open(readRange);
  status.openedMs = performance.now() - started;
  const h = file.header;
  if (file.root < 0) throw new Error(`${p.file}: the file has no voxels to draw`);
  if (p.material && !file.hasMaterials()) {
    throw new Error(`${p.file}: color=material: the file has no material channel (built from a mesh with fewer than two materials)`);
  }
  const renderer = new Renderer(canvas);
  const gl = renderer.gl;
  const pool = new Pool(p.workers);

  // resident nodes: key → {res, lastUsed}; keys: "v<i>" voxels, "s<i>" source triangles
  const resident = new Map();
  const inflight = new Set();
  const failed = new Map();
  let residentBytes = 0;
  let frameNo = 0;
  let dirty = true;

  function request(key, i) {
    if (inflight.has(key) || resident.has(key) || failed.has(key)) return;
    inflight.add(key);
    status.requests++;
    const e = file.nodes[i];
    const kind = key[0] === 's' ? 'source' : 'voxels';
    pool.run({ kind, url: p.url, entry: e, material: p.material, voxelSize: h.voxelSize }).then((r) => {
      inflight.delete(key);
      status.bytesFetched += r.fetched;
      if (!r.ok) {
        failed.set(key, r.error);
        showError(new Error(`node ${i}: ${r.error}`));
        return;
      }
      const res = kind === 'source' ? renderer.uploadSource(r) : renderer.uploadVoxels(r.rec);
      if (kind === 'voxels' && robustWaiting.has(i)) robustWaiting.get(i)(r.rec);
      resident.set(key, { res, lastUsed: frameNo });
      residentBytes += res.bytes;
      dirty = true;
    });
  }

  // the framing box: robust bounds of the coarsest level with enough voxels (camera.rs)
  const robustWaiting = new Map();
  const level = robustLevel(file);
  const levelNodes = file.nodes.filter((e) => e.level === level);
  const recs = await Promise.all(levelNodes.map((e) => new Promise((resolve) => {
    robustWaiting.set(e.index, resolve);
    request(`v${e.index}`, e.index);
  })));
  robustWaiting.clear();
  const bounds = robustBounds(h, level, levelNodes.map((e, k) => [e, recs[k]]));
  status.framedMs = performance.now() - started;

  // up: the URL, the manifest's input.up, the model's shape, +Y (render's rule)
  let up = p.up;
  if (!up) {
    const u = file.manifest?.input?.up;
    if (Array.isArray(u) && u.length === 3 && u.every((x) => typeof x === 'number')) up = u;
  }
  up = up ?? upFromShape(bounds) ?? [0, 1, 0];

  const home = { direction: p.direction, zoom: p.zoom, target: p.target };
  const view = { ...defaultView(), direction: p.direction, up, fovYDeg: p.fov, zoom: p.zoom, target: p.target };

  function resize() {
    let w;
    let hgt;
    if (p.size) {
      [w, hgt] = p.size;
      canvas.style.width = `${w / devicePixelRatio}px`;
      canvas.style.height = `${hgt / devicePixelRatio}px`;
    } else {
      w = Math.max(1, Math.round(window.innerWidth * devicePixelRatio));
      hgt = Math.max(1, Math.round(window.innerHeight * devicePixelRatio));
      canvas.style.width = '100vw';
      canvas.style.height = '100vh';
    }
    canvas.width = w;
    canvas.height = hgt;
    view.width = w;
    view.height = hgt;
    dirty = true;
  }
  resize();
  window.addEventListener('resize', () => { if (!p.size) resize(); });

  // occlusion culling (Chajdas et al. section 4, with occlusion queries): a node of the cut
  // that is not resident is first tested, its box (grown by a voxel of the stand-in drawn
  // for it, so the stand-in's coarser voxels cannot hide it) drawn after everything else with
  // depth test on and colour and depth writes off inside an ANY_SAMPLES_PASSED_CONSERVATIVE
  // query; it is fetched only once a test passed, and a node whose box is hidden is neither
  // fetched nor drawn while it stays hidden (`occluded`). Tests are read a frame or more later.
  // i → {query, hidden, pendingScene, resultScene}; a scene is one camera and one set of draws
  // and tests, and a result counts for completeness only if it was taken in the scene drawn now.
  const occ = new Map();
  let sceneVersion = 0;
  let lastSceneKey = '';

  function collectQueries() {
    let changed = false;
    for (const o of occ.values()) {
      if (!o.pendingScene) continue;
      if (!gl.getQueryParameter(o.query, gl.QUERY_RESULT_AVAILABLE)) continue;
      const hidden = gl.getQueryParameter(o.query, gl.QUERY_RESULT) === 0;
      // a first answer lets the node be fetched; a changed one changes the frame
      if (hidden !== o.hidden || !o.resultScene) changed = true;
      o.hidden = hidden;
      o.resultScene = o.pendingScene;
      o.pendingScene = 0;
    }
    return changed;
  }

  function drawFrame() {
    const t0 = performance.now();
    frameNo++;
    const shot = frameShot(bounds, view);
    const useOcclusion = p.occlusion && renderer.queriesOk;
    if (useOcclusion) collectQueries();
    const ctx = new CutContext(file, shot, p.error);
    const origin = shot.target;
    const want = [];
    const tests = [];
    let occluded = 0;
    const fwd = vec.norm(vec.sub(shot.target, shot.eye));
    const depthOf = (i) => vec.dot(vec.sub(vec.scale(vec.add(ctx.boxes[i].min, ctx.boxes[i].max), 0.5), shot.eye), fwd);

    // the nodes to draw for the subtree of i, front to back, or null if it cannot be covered
    // yet (then its parent stands in); `standIn` is the voxel edge of the resident ancestor
    // that would be drawn in its place
    function cover(i, standIn) {
      if (!ctx.visible(i)) return [];
      const e = file.nodes[i];
      const vkey = `v${i}`;
      const edge = voxelSizeAt(h, e.level);
      if (ctx.refines(i)) {
        const kids = file.children[i].slice().sort((a, b) => depthOf(a) - depthOf(b));
        const below = resident.has(vkey) ? edge : standIn;
        const lists = kids.map((k) => cover(k, below));
        if (lists.every((l) => l !== null)) return lists.flat();
        return resident.has(vkey) ? [{ i, key: vkey, standIn: true }] : null;
      }
      const err = ctx.error(i);
      const over = e.level === 0 && !(err <= p.error);
      const key = over && p.source && e.channels[CHANNEL_SOURCE_TRIANGLES] ? `s${i}` : vkey;
      if (resident.has(key)) return [{ i, key }];
      if (useOcclusion) {
        const o = occ.get(i);
        const grow = Math.max(edge, standIn ?? 0);
        const b = ctx.boxes[i];
        const inside = [0, 1, 2].every((a) => shot.eye[a] > b.min[a] - grow && shot.eye[a] < b.max[a] + grow);
        if (!inside) {
          tests.push({ i, grow });
          if (!o || !o.resultScene) return resident.has(vkey) ? [{ i, key: vkey, standIn: true }] : null;
          if (o.hidden) {
            occluded++;
            return [];
          }
        }
      }
      want.push({ key, i, level: e.level, err });
      return resident.has(vkey) ? [{ i, key: vkey, standIn: true }] : null;
    }

    const list = cover(file.root, null) ?? [];
    const sceneKey = JSON.stringify([shot.eye, shot.target, shot.up, shot.fovY, shot.width, shot.height])
      + list.map((d) => d.key).join(',') + '|' + tests.map((t) => t.i).join(',');
    if (sceneKey !== lastSceneKey) {
      lastSceneKey = sceneKey;
      sceneVersion++;
    }

    // requests: coarse levels first, then the largest error
    want.sort((a, b) => b.level - a.level || b.err - a.err);
    let starved = false;
    for (const w of want) {
      if (inflight.size >= 6) break;
      if (residentBytes > p.budget) {
        starved = true;
        break;
      }
      request(w.key, w.i);
    }

    // progressive=0: draw only frames without missing nodes, and those that test nodes for
    // occlusion before they are fetched (as `view --fly` draws complete frames)
    const testing = tests.some((t) => !occ.get(t.i)?.resultScene);
    if (!p.progressive && !testing && (want.length > 0 || inflight.size > 0)) {
      last = { want: want.length, standIns: 1, tests: [] };
      status.wanted = want.length;
      return;
    }

    // draw
    const vp = columnMajor(viewProj(shot, origin, true));
    const rel = (a) => a.map((c, k) => c - origin[k]);
    const draws = [];
    const levels = new Set();
    for (const d of list) {
      const r = resident.get(d.key);
      r.lastUsed = frameNo;
      const e = file.nodes[d.i];
      const edge = voxelSizeAt(h, e.level);
      const corner = rel([0, 1, 2].map((a) => h.origin[a] + edge * 256 * [e.x, e.y, e.z][a]));
      levels.add(e.level);
      draws.push({ res: r.res, corner, edge });
    }
    const boxes = [];
    for (const t of tests) {
      let o = occ.get(t.i);
      if (!o) occ.set(t.i, (o = { query: gl.createQuery(), hidden: false, pendingScene: 0, resultScene: 0 }));
      if (o.pendingScene) continue;
      o.pendingScene = sceneVersion;
      const b = ctx.boxes[t.i];
      boxes.push({ min: rel(b.min.map((c) => c - t.grow)), max: rel(b.max.map((c) => c + t.grow)), query: o.query });
    }
    renderer.draw(shot.width, shot.height, {
      viewProj: vp, eye: rel(shot.eye), light: lightDirection(shot), twoSided: p.twoSided,
    }, draws, boxes);
    fence = gl.fenceSync(gl.SYNC_GPU_COMMANDS_COMPLETE, 0);
    gl.flush();

    // the memory budget: least recently used nodes not drawn this frame go first
    if (residentBytes > p.budget) {
      const old = [...resident.entries()].filter(([, r]) => r.lastUsed !== frameNo).sort((a, b) => a[1].lastUsed - b[1].lastUsed);
      for (const [key, r] of old) {
        if (residentBytes <= p.budget) break;
        renderer.free(r.res);
        residentBytes -= r.res.bytes;
        resident.delete(key);
      }
    }

    const frameMs = performance.now() - t0;
    last = {
      want: want.length,
      standIns: list.filter((d) => d.standIn).length,
      tests: tests.map((t) => t.i),
    };
    Object.assign(status, {
      nodes: list.length,
      frameMs,
      occluded,
      wanted: want.length,
      resident: resident.size,
      residentBytes,
      starved,
      levels: [...levels].sort((a, b) => a - b),
      drawn: list.map((d) => d.i).sort((a, b) => a - b),
      camera: { eye: shot.eye, target: shot.target, up: shot.up, zoom: view.zoom },
    });
  }

  // complete: nothing missing or on its way, no stand-in drawn, and every query of the scene
  // drawn now answered (so the occlusion state it was drawn with is settled)
  let last = null;
  function settle() {
    if (!last) return;
    const answered = last.tests.every((i) => occ.get(i)?.resultScene === sceneVersion);
    // results of an older scene only, none on its way: draw again to test in this one
    if (!answered && !dirty && last.tests.every((i) => !occ.get(i)?.pendingScene)) dirty = true;
    const complete = last.want === 0 && last.standIns === 0 && inflight.size === 0 && answered && !status.error && !dirty && !fence;
    status.complete = complete;
    if (complete && status.firstCompleteMs === null) status.firstCompleteMs = performance.now() - started;
    const mb = (b) => `${(b / 1048576).toFixed(2)} MB`;
    overlay.textContent = `levels ${status.levels.join(',')} · ${status.nodes} nodes${status.occluded ? ` (${status.occluded} occluded)` : ''} · `
      + `${mb(status.bytesFetched)} fetched of ${mb(h.fileSize)} · ${mb(residentBytes)} resident · ${status.frameMs.toFixed(1)} ms`
      + (complete ? '' : ` · loading ${last.want + inflight.size}`);
  }

  // the last frame's fence: no new frame is drawn before the GPU has finished the last one
  // (a software rasterizer would otherwise queue a frame per arriving node), and a frame
  // counts as drawn (for `complete`) once it has finished
  let fence = null;
  function gpuBusy() {
    if (!fence) return false;
    if (gl.getSyncParameter(fence, gl.SYNC_STATUS) !== gl.SIGNALED) return true;
    gl.deleteSync(fence);
    fence = null;
    return false;
  }

  function loop() {
    try {
      if (gpuBusy()) {
        // wait
      } else if (dirty) {
        dirty = false;
        drawFrame();
      } else if (p.occlusion && renderer.queriesOk && collectQueries()) {
        // a node turned hidden or visible: draw again
        dirty = true;
      }
      settle();
    } catch (e) {
      showError(e);
      return;
    }
    requestAnimationFrame(loop);
  }
  requestAnimationFrame(loop);

  // interaction: orbit (left drag), pan (right or shift drag), zoom (wheel), R resets
  let drag = null;
  canvas.addEventListener('contextmenu', (ev) => ev.preventDefault());
  canvas.addEventListener('pointerdown', (ev) => {
    drag = { x: ev.clientX, y: ev.clientY, pan: ev.button === 2 || ev.shiftKey };
    canvas.setPointerCapture(ev.pointerId);
  });
  canvas.addEventListener('pointerup', () => { drag = null; });
  canvas.addEventListener('pointermove', (ev) => {
    if (!drag) return;
    const dx = (ev.clientX - drag.x) * devicePixelRatio;
    const dy = (ev.clientY - drag.y) * devicePixelRatio;
    drag.x = ev.clientX;
    drag.y = ev.clientY;
    const shot = frameShot(bounds, view);
    const fwd = vec.norm(vec.sub(shot.target, shot.eye));
    const right = vec.norm(vec.cross(fwd, shot.up));
    if (drag.pan) {
      const dist = vec.len(vec.sub(shot.eye, shot.target));
      const perPixel = (2 * dist * Math.tan(shot.fovY / 2)) / shot.height;
      view.target = vec.add(shot.target, vec.add(vec.scale(right, -dx * perPixel), vec.scale(shot.up, dy * perPixel)));
    } else {
      const rot = (v, axis, angle) => {
        const c = Math.cos(angle);
        const s = Math.sin(angle);
        const k = vec.norm(axis);
        return vec.add(vec.add(vec.scale(v, c), vec.scale(vec.cross(k, v), s)), vec.scale(k, vec.dot(k, v) * (1 - c)));
      };
      let d = vec.norm(view.direction);
      d = rot(d, view.up, -dx * 0.005);
      const tilted = rot(d, right, dy * 0.005);
      if (Math.abs(vec.dot(vec.norm(tilted), vec.norm(view.up))) < 0.995) d = tilted;
      view.direction = d;
    }
    dirty = true;
  });
  canvas.addEventListener('wheel', (ev) => {
    ev.preventDefault();
    view.zoom *= Math.exp(-ev.deltaY * 0.0015);
    dirty = true;
  }, { passive: false });
  window.addEventListener('keydown', (ev) => {
    if (ev.key === 'r' || ev.key === 'R') {
      Object.assign(view, home);
      dirty = true;
    }
  });
}

main().catch(showError);
