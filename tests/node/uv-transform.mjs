// What three.js's GLTFLoader makes of a glTF's texture coordinates: loads FILE.gltf (its
// buffers and images named by URI are read from disk as data URIs) and prints, for every
// vertex of its first primitive, the position and the texture coordinates after the base
// colour texture's matrix (KHR_texture_transform), as JSON on stdout:
// [{"position":[x,y,z],"uv":[u,v]}, ...]. The image is not decoded (a stub stands in for
// createImageBitmap): only the transform is asked for.
// Usage: node tests/node/uv-transform.mjs FILE.gltf
import fs from 'node:fs';
import path from 'node:path';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { Vector3 } from 'three';

const file = process.argv[2];
const json = JSON.parse(fs.readFileSync(file, 'utf8'));
const dir = path.dirname(file);
const dataUri = (uri, mime) =>
  uri.startsWith('data:')
    ? uri
    : `data:${mime};base64,${fs.readFileSync(path.join(dir, decodeURIComponent(uri))).toString('base64')}`;
for (const b of json.buffers || []) if (b.uri) b.uri = dataUri(b.uri, 'application/octet-stream');
for (const i of json.images || []) if (i.uri) i.uri = dataUri(i.uri, 'image/png');

// the loader decodes images with createImageBitmap, which node lacks: the texture's size is
// all the transform could depend on, and it does not
globalThis.createImageBitmap = async () => ({ width: 4, height: 4, close() {} });
// and the browser globals its file loader reports progress with
globalThis.self = globalThis;
globalThis.ProgressEvent ??= class extends Event {
  constructor(type, init) {
    super(type);
    Object.assign(this, init);
  }
};

new GLTFLoader().parse(
  JSON.stringify(json),
  '',
  (gltf) => {
    let mesh = null;
    gltf.scene.traverse((o) => {
      if (o.isMesh && !mesh) mesh = o;
    });
    const map = mesh.material.map;
    if (!map) throw new Error('the material has no map');
    if (map.matrixAutoUpdate) map.updateMatrix();
    const g = mesh.geometry;
    const uvName = map.channel ? `uv${map.channel}` : 'uv';
    const out = [];
    for (let i = 0; i < g.attributes.position.count; i++) {
      const p = g.attributes.position;
      const t = g.attributes[uvName];
      const uv = new Vector3(t.getX(i), t.getY(i), 1).applyMatrix3(map.matrix);
      out.push({ position: [p.getX(i), p.getY(i), p.getZ(i)], uv: [uv.x, uv.y] });
    }
    process.stdout.write(JSON.stringify(out));
  },
  (e) => {
    console.error(`${file}: three.js could not load it: ${e}`);
    process.exit(2);
  },
);
