// Helpers shared by the fit page and the bank gallery (classic script: pages must open from disk).
"use strict";
window.ZV = (function () {
  function fail(message) {
    const box = document.getElementById("error");
    if (box) { box.textContent = message; box.hidden = false; }
    console.error(message);
  }

  function b64ToBuffer(b64) {
    const bin = atob(b64);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return bytes.buffer;
  }

  function parseGLB(b64) {
    return new Promise(function (resolve, reject) {
      new THREE.GLTFLoader().parse(b64ToBuffer(b64), "", resolve, reject);
    });
  }

  function makeRenderer(canvas) {
    const renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: true, preserveDrawingBuffer: true });
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.outputColorSpace = THREE.SRGBColorSpace;
    return renderer;
  }

  function addLights(scene) {
    scene.add(new THREE.HemisphereLight(0xffffff, 0x50555c, 1.6));
    const key = new THREE.DirectionalLight(0xffffff, 1.6);
    key.position.set(0.4, 1.0, 0.8);
    scene.add(key);
  }

  // Skinned meshes move far from their rest-pose bounds (the fit's root motion): never cull them.
  // Lambert shading (zooctl's previews shade the same way) instead of the GLB's PBR material: its
  // shader compiles and draws several times faster where WebGL runs on the CPU (BENCHMARKS.md).
  function prepareModel(root) {
    root.traverse(function (o) {
      if (!o.isMesh) return;
      o.frustumCulled = false;
      const m = o.material;
      if (m && m.isMeshStandardMaterial) {
        o.material = new THREE.MeshLambertMaterial({ color: m.color, map: m.map, vertexColors: m.vertexColors, side: m.side });
        m.dispose();
      }
    });
  }

  // The posed (skinned) bounding box of every mesh under root, in world space.
  function posedBox(root) {
    const box = new THREE.Box3();
    root.updateMatrixWorld(true);
    root.traverse(function (o) {
      if (o.isSkinnedMesh) {
        o.computeBoundingBox();
        box.union(o.boundingBox.clone().applyMatrix4(o.matrixWorld));
      } else if (o.isMesh) {
        box.expandByObject(o);
      }
    });
    return box;
  }

  function fmt(x, digits) {
    if (x === null || x === undefined) return "n/a";
    if (typeof x !== "number") return String(x);
    return x.toFixed(digits === undefined ? 3 : digits);
  }

  function el(tag, attrs, children) {
    const e = document.createElement(tag);
    for (const k in attrs || {}) {
      if (k === "text") e.textContent = attrs[k]; else e.setAttribute(k, attrs[k]);
    }
    (children || []).forEach(function (c) { e.appendChild(c); });
    return e;
  }

  window.addEventListener("error", function (ev) { fail("viewer error: " + ev.message); });
  window.addEventListener("unhandledrejection", function (ev) { fail("viewer error: " + ev.reason); });

  return { fail: fail, parseGLB: parseGLB, makeRenderer: makeRenderer, addLights: addLights,
           prepareModel: prepareModel, posedBox: posedBox, fmt: fmt, el: el };
})();
