// Validate a .glb with the Khronos glTF-Validator and print its JSON report on stdout.
// Usage: node gltf_validate.js <folder of the gltf-validator package> <file.glb>
// (the package is installed outside the repository by tests/io/test_gltf_materials.py)
"use strict";
const fs = require("fs");
const validator = require(process.argv[2]);
const data = new Uint8Array(fs.readFileSync(process.argv[3]));
validator
  .validateBytes(data, { maxIssues: 1000, format: "glb" })
  .then((report) => process.stdout.write(JSON.stringify(report)))
  .catch((err) => {
    process.stderr.write(String(err) + "\n");
    process.exit(2);
  });
