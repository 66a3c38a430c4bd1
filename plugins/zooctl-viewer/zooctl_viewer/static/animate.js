// Sampled motions beside the character's real clip: one clock, one orbit shared by every panel.
"use strict";
(function () {
  const D = window.ZOOCTL_VIEW;
  if (!D || D.kind !== "animate") { ZV.fail("data.js is missing or is not an animate folder's data"); return; }
  const $ = function (id) { return document.getElementById(id); };
  $("title").textContent = "motions for " + D.target;
  $("subtitle").textContent = [D.panels.filter(function (p) { return !p.real; }).length + " sampled motions",
    "prior " + D.prior, D.temperature !== null && D.temperature !== undefined ? "temperature " + D.temperature : null,
    "seed " + D.seed].filter(Boolean).join(" \u00b7 ");

  const views = [];
  let duration = 0, t = 0, playing = true, last = 0, syncing = false, loaded = 0;

  D.panels.forEach(function (p, i) {
    const canvas = ZV.el("canvas", {});
    const stage = ZV.el("div", { class: "stage" }, [canvas]);
    $("panels").appendChild(ZV.el("section", { class: "panel" + (p.real ? " real" : ""), "data-panel": String(i) }, [
      ZV.el("div", { class: "panel-head" }, [ZV.el("strong", { text: p.title }), ZV.el("span", { class: "small dim", text: p.note })]),
      stage,
    ]));
    const renderer = ZV.makeRenderer(canvas);
    const scene = new THREE.Scene();
    scene.background = new THREE.Color(p.real ? 0x26303a : 0x2a2f36);
    ZV.addLights(scene);
    const camera = new THREE.PerspectiveCamera(30, 4 / 3, 0.01, 1000);
    const controls = new THREE.OrbitControls(camera, canvas);
    const v = { renderer: renderer, scene: scene, camera: camera, controls: controls, stage: stage, mixer: null, action: null, model: null, skeleton: null };
    views.push(v);
    controls.addEventListener("change", function () { if (!syncing) syncFrom(v); });
    new ResizeObserver(function () {
      const r = stage.getBoundingClientRect();
      renderer.setSize(Math.max(1, Math.round(r.width)), Math.max(1, Math.round(r.height)), false);
      camera.aspect = r.width / Math.max(1, r.height);
      camera.updateProjectionMatrix();
    }).observe(stage);
    ZV.parseGLB(p.glb).then(function (gltf) {
      v.model = gltf.scene;
      ZV.prepareModel(v.model);
      scene.add(v.model);
      v.skeleton = new THREE.SkeletonHelper(v.model);
      v.skeleton.visible = $("skeleton").checked;
      scene.add(v.skeleton);
      const clip = gltf.animations[0];
      if (clip) {
        v.mixer = new THREE.AnimationMixer(v.model);
        v.action = v.mixer.clipAction(clip);
        v.action.play();
        v.duration = clip.duration;
        duration = Math.max(duration, clip.duration);
      }
      if (i === 0) frame(v);
      if (++loaded === D.panels.length) { syncFrom(views[0]); requestAnimationFrame(tick); }
    }).catch(function (err) { ZV.fail("could not read " + p.title + ": " + err); });
  });

  // Every panel sees its character from the same place: the first panel's framing, then any orbit.
  function frame(v) {
    const box = ZV.posedBox(v.model);
    const c = box.getCenter(new THREE.Vector3());
    const r = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-3);
    const d = r / Math.sin(THREE.MathUtils.degToRad(v.camera.fov / 2)) * 1.2;
    v.camera.position.set(c.x + d * 0.8, c.y + d * 0.35, c.z + d * 0.5);
    v.camera.near = d / 100; v.camera.far = d * 100;
    v.camera.updateProjectionMatrix();
    v.controls.target.copy(c);
    v.controls.update();
  }
  function syncFrom(src) {
    syncing = true;
    views.forEach(function (v) {
      if (v === src) return;
      v.camera.position.copy(src.camera.position);
      v.camera.near = src.camera.near; v.camera.far = src.camera.far;
      v.camera.updateProjectionMatrix();
      v.controls.target.copy(src.controls.target);
      v.controls.update();
    });
    syncing = false;
  }

  function show(time) {
    t = time;
    views.forEach(function (v) {
      if (v.action) { v.action.time = v.duration > 0 ? t % v.duration : 0; v.mixer.update(0); }
    });
    $("slider").value = String(duration > 0 ? Math.round(1000 * (t % duration) / duration) : 0);
    $("time-label").textContent = ZV.fmt(duration > 0 ? t % duration : 0, 2) + " / " + ZV.fmt(duration, 2) + " s";
  }

  function tick(now) {
    const dt = last ? (now - last) / 1000 : 0;
    last = now;
    show(playing ? t + dt : t);
    views.forEach(function (v) { if (v.model) v.renderer.render(v.scene, v.camera); });
    if (!window.ZOOCTL_FIRST_FRAME_MS) { window.ZOOCTL_FIRST_FRAME_MS = performance.now(); document.body.dataset.ready = "1"; }
    requestAnimationFrame(tick);
  }

  function setPlaying(on) { playing = on; $("play").textContent = playing ? "Pause" : "Play"; }
  $("play").addEventListener("click", function () { setPlaying(!playing); });
  $("slider").addEventListener("input", function (e) { setPlaying(false); show(duration * e.target.value / 1000); });
  $("skeleton").addEventListener("change", function (e) { views.forEach(function (v) { if (v.skeleton) v.skeleton.visible = e.target.checked; }); });
  window.addEventListener("keydown", function (e) { if (e.key === " ") { e.preventDefault(); setPlaying(!playing); } });
  window.zooctlShow = function (time) { setPlaying(false); show(time); };
})();
