// Validates glTF 2.0 files with Khronos' gltf-validator (npm) for the corpus test in
// tests/api.rs: one JSON line per file with its error count, the extensions it requires
// and the validator's triangle count and whether it has textures. External resources are
// read beside the file, percent-decoded, as the glTF spec says.
// Usage: GLTF_VALIDATOR=.../node_modules/gltf-validator node validate.js FILE...
const fs = require('fs');
const path = require('path');
const validator = require(process.env.GLTF_VALIDATOR || 'gltf-validator');

function readBeside(dir) {
  return (uri) => new Promise((resolve, reject) => {
    fs.readFile(path.resolve(dir, decodeURIComponent(uri)), (error, data) =>
      error ? reject(error.toString()) : resolve(new Uint8Array(data)));
  });
}

(async () => {
  for (const file of process.argv.slice(2)) {
    let line;
    try {
      const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
        uri: path.basename(file),
        externalResourceFunction: readBeside(path.dirname(file)),
      });
      const info = report.info || {};
      line = {
        file,
        errors: report.issues.numErrors,
        codes: [...new Set(report.issues.messages.filter((m) => m.severity === 0).map((m) => m.code))],
        required: info.extensionsRequired || [],
        triangles: info.totalTriangleCount || 0,
        textures: Boolean(info.hasTextures),
      };
    } catch (error) {
      line = { file, errors: -1, codes: [String(error)], required: [], triangles: 0, textures: false };
    }
    console.log(JSON.stringify(line));
  }
})();
