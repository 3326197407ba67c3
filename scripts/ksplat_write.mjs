// Writes a .ksplat with GaussianSplats3D's own generator, the calls its util/create-ksplat.js
// makes (npm @mkkellogg/gaussian-splats-3d, with three). Used by scripts/make_splat_fixtures.py.
//
//   node scripts/ksplat_write.mjs IN.ply OUT.ksplat LEVEL SH_DEGREE BLOCK_SIZE BUCKET_SIZE
//
// Run it where node can import '@mkkellogg/gaussian-splats-3d' and 'three' (NODE_PATH does not
// apply to ES modules: the script is copied next to a node_modules folder by the caller).
import * as fs from 'fs';
import * as GaussianSplats3D from '@mkkellogg/gaussian-splats-3d';
import * as THREE from 'three';

const [input, output, level, shDegree, blockSize, bucketSize] = process.argv.slice(2);
const data = fs.readFileSync(input);
const buffer = data.buffer.slice(data.byteOffset, data.byteOffset + data.byteLength);
const splats = GaussianSplats3D.PlyParser.parseToUncompressedSplatArray(buffer, parseInt(shDegree));
// Alpha removal threshold 1 (the tool's default), one section, the scene centre at the origin.
const generator = GaussianSplats3D.SplatBufferGenerator.getStandardGenerator(
    1, parseInt(level), 0, new THREE.Vector3(0, 0, 0), parseFloat(blockSize), parseInt(bucketSize));
const splatBuffer = generator.generateFromUncompressedSplatArray(splats);
fs.writeFileSync(output, Buffer.from(splatBuffer.bufferData));
