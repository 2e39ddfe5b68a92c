// Validates a glTF file with the Khronos glTF validator (npm: gltf-validator): node validate_gltf.js MODULES FILE
// prints {"errors", "warnings", "messages"} as JSON (MODULES: the folder holding node_modules/gltf-validator).
const fs = require("fs");
const validator = require(process.argv[2] + "/node_modules/gltf-validator");
validator
  .validateBytes(new Uint8Array(fs.readFileSync(process.argv[3])), { maxIssues: 100 })
  .then((r) => {
    const { numErrors, numWarnings, messages } = r.issues;
    console.log(JSON.stringify({ errors: numErrors, warnings: numWarnings, messages: messages }));
  })
  .catch((e) => {
    console.error(String(e));
    process.exit(1);
  });
