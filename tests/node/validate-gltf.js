// Validates a glTF binary with the Khronos glTF validator (npm gltf-validator) and prints its
// report as JSON on stdout; exit status 0 when the validator ran (the caller reads the counts).
// Usage: node tests/node/validate-gltf.js FILE.glb
'use strict';
const fs = require('fs');
const validator = require('gltf-validator');

const file = process.argv[2];
validator
  .validateBytes(new Uint8Array(fs.readFileSync(file)), { maxIssues: 100 })
  .then((report) => {
    process.stdout.write(JSON.stringify(report));
  })
  .catch((e) => {
    console.error(`${file}: the validator failed: ${e}`);
    process.exit(2);
  });
