// The fit page: the fitted character in 3D beside the input video, one frame slider for both.
"use strict";
(function () {
  performance.mark("zooctl:scripts-loaded");  // three.js, the data and this script are parsed
  const D = window.ZOOCTL_VIEW;
  if (!D || D.kind !== "fit") { ZV.fail("data.js is missing or is not a fit's data"); return; }
  const R = D.record;
  const T = D.frames, W = D.width, H = D.height;
  const $ = function (id) { return document.getElementById(id); };

  // --- page text ----------------------------------------------------------------------------
  document.title = "zooctl view " + D.name;
  $("title").textContent = "fit " + D.name;
  if (D.back) { $("back").href = D.back; $("back").hidden = false; }
  const wall = R.timings && R.timings.total_wall;
  $("subtitle").textContent = [
    "video " + (R.video || R.source), T + " frames at " + ZV.fmt(D.fps, 1) + " fps", W + "x" + H,
    "template " + R.template, R.config && R.config.preset ? "preset " + R.config.preset : null,
    wall ? "fitted in " + Math.round(wall) + " s" : null,
  ].filter(Boolean).join(" \u00b7 ");
  $("camera-note").textContent = "Input view: the fitted camera (" + D.camera.source + "), focal " +
    ZV.fmt(D.camera.fx, 1) + " px. Drag to orbit (switches to the free view, where the orange frustum is the input camera), scroll to zoom.";
  for (const s of ["stage3d", "stage2d"]) $(s).style.aspectRatio = W + " / " + H;
  $("frame").src = D.frame_files[0];  // loads while three.js reads the GLB
  $("overlay").src = D.overlay_files[0];
  fillMetrics();
  fillRetrieval();
  fillNotes();

  // --- 3D -----------------------------------------------------------------------------------
  const canvas = $("canvas3d");
  const renderer = ZV.makeRenderer(canvas);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x2a2f36);
  ZV.addLights(scene);

  const c2w = new THREE.Matrix4();
  const m = D.camera.camera_to_world;
  c2w.set(m[0][0], m[0][1], m[0][2], m[0][3], m[1][0], m[1][1], m[1][2], m[1][3],
          m[2][0], m[2][1], m[2][2], m[2][3], m[3][0], m[3][1], m[3][2], m[3][3]);
  const inputCam = new THREE.PerspectiveCamera();
  inputCam.matrixAutoUpdate = false;
  inputCam.matrix.copy(c2w);
  inputCam.matrix.decompose(inputCam.position, inputCam.quaternion, inputCam.scale);
  inputCam.updateMatrixWorld(true);
  const vfov = 2 * Math.atan(H / 2 / D.camera.fy) * 180 / Math.PI;
  const freeCam = new THREE.PerspectiveCamera(vfov, W / H, 0.01, 1000);
  const controls = new THREE.OrbitControls(freeCam, canvas);
  controls.enableDamping = false;
  let mode = "input", dirty = true;

  // The input camera's pinhole (focal lengths, principal point) as an off-centre frustum.
  function inputProjection(cam, near, far) {
    const c = D.camera;
    cam.near = near; cam.far = far;
    cam.projectionMatrix.makePerspective(
      -near * c.cx / c.fx, near * (W - c.cx) / c.fx, near * c.cy / c.fy, -near * (H - c.cy) / c.fy, near, far);
    cam.projectionMatrixInverse.copy(cam.projectionMatrix).invert();
  }

  let model = null, mixer = null, action = null, skeleton = null, frustum = null, frame = 0;

  function setFrame(i) {
    frame = Math.max(0, Math.min(T - 1, i | 0));
    if (action) { action.time = frame / D.fps; mixer.update(0); }
    $("slider").value = String(frame);
    $("frame-label").textContent = "frame " + frame + " / " + (T - 1) + "  (" + ZV.fmt(frame / D.fps, 2) + " s)";
    $("frame").src = D.frame_files[frame];
    $("overlay").src = D.overlay_files[frame];
    const iou = D.silhouette_iou[frame];
    $("frame-iou").textContent = "IoU this frame " + ZV.fmt(iou);
    dirty = true;
  }

  function setMode(next) {
    mode = next;
    $("view-input").classList.toggle("on", mode === "input");
    $("view-free").classList.toggle("on", mode === "free");
    if (frustum) frustum.visible = mode === "free";
    if (mode === "input") syncFreeToInput();
    dirty = true;
  }

  // The free camera starts where the input camera is, orbiting a point at the animal's depth on
  // the input camera's axis (so the first drag does not jump).
  function syncFreeToInput() {
    if (!model) return;
    const box = ZV.posedBox(model);
    const centre = box.getCenter(new THREE.Vector3());
    const dir = new THREE.Vector3(0, 0, -1).applyQuaternion(inputCam.quaternion);
    const dist = Math.max(centre.clone().sub(inputCam.position).dot(dir), 1e-3);
    freeCam.position.copy(inputCam.position);
    freeCam.quaternion.copy(inputCam.quaternion);
    freeCam.fov = vfov; freeCam.near = dist / 100; freeCam.far = dist * 100;
    freeCam.updateProjectionMatrix();
    controls.target.copy(inputCam.position).addScaledVector(dir, dist);
    controls.update();
  }

  function resize() {
    const rect = $("stage3d").getBoundingClientRect();
    renderer.setSize(Math.max(1, Math.round(rect.width)), Math.max(1, Math.round(rect.height)), false);
    dirty = true;
  }
  new ResizeObserver(resize).observe($("stage3d"));

  controls.addEventListener("start", function () { if (mode === "input") setMode("free"); });
  controls.addEventListener("change", function () { dirty = true; });

  // --- transport ----------------------------------------------------------------------------
  let playing = false, playStart = 0, playFrom = 0;
  function setPlaying(on) {
    playing = on && T > 1;
    $("play").textContent = playing ? "Pause" : "Play";
    playStart = performance.now(); playFrom = frame;
  }
  $("slider").max = String(T - 1);
  $("slider").addEventListener("input", function (e) { setPlaying(false); setFrame(+e.target.value); });
  $("play").addEventListener("click", function () { setPlaying(!playing); });
  $("view-input").addEventListener("click", function () { setMode("input"); });
  $("view-free").addEventListener("click", function () { setMode("free"); });
  $("skeleton").addEventListener("change", function (e) { if (skeleton) skeleton.visible = e.target.checked; dirty = true; });
  $("show-overlay").addEventListener("change", function (e) { $("overlay").style.visibility = e.target.checked ? "visible" : "hidden"; });
  window.addEventListener("keydown", function (e) {
    if (e.target.tagName === "INPUT" && e.target.type !== "range" && e.target.type !== "checkbox") return;
    if (e.key === " ") { e.preventDefault(); setPlaying(!playing); }
    else if (e.key === "ArrowRight") { setPlaying(false); setFrame(frame + 1); }
    else if (e.key === "ArrowLeft") { setPlaying(false); setFrame(frame - 1); }
    else if (e.key === "i" || e.key === "I") setMode("input");
    else if (e.key === "f" || e.key === "F") setMode("free");
  });

  function tick(now) {
    if (playing) {
      const f = (playFrom + Math.floor((now - playStart) / 1000 * D.fps)) % T;
      if (f !== frame) setFrame(f);
    }
    if (dirty && model) {
      renderer.render(scene, mode === "input" ? inputCam : freeCam);
      dirty = false;
      if (!window.ZOOCTL_FIRST_FRAME_MS) { performance.mark("zooctl:first-render"); firstFrameDrawn(); }
    }
    requestAnimationFrame(tick);
  }

  // For tests and the benchmark: when the first frame of the character (and of the video) is on screen.
  function firstFrameDrawn() {
    window.ZOOCTL_FIRST_FRAME_MS = -1;
    $("frame").decode().catch(function () {}).then(function () {
      window.ZOOCTL_FIRST_FRAME_MS = performance.now();
      document.body.dataset.ready = "1";
      preload();
    });
  }

  function preload() {
    const keep = [];
    D.frame_files.concat(D.overlay_files).forEach(function (src) { const im = new Image(); im.src = src; keep.push(im); });
    window.ZOOCTL_PRELOADED = keep;
  }

  // Test hooks (and handy from the console): show frame i in the given view.
  window.zooctlShow = function (i, view) { setPlaying(false); setMode(view || mode); setFrame(i); };

  ZV.parseGLB(D.glb).then(function (gltf) {
    performance.mark("zooctl:glb-parsed");
    model = gltf.scene;
    ZV.prepareModel(model);
    scene.add(model);
    const clip = gltf.animations.find(function (a) { return a.name === "fit"; }) || gltf.animations[0];
    if (clip) {
      mixer = new THREE.AnimationMixer(model);
      action = mixer.clipAction(clip);
      action.play();
    }
    skeleton = new THREE.SkeletonHelper(model);
    skeleton.visible = $("skeleton").checked;
    scene.add(skeleton);
    setFrame(0);
    const box = ZV.posedBox(model);
    const size = box.getSize(new THREE.Vector3()).length();
    const dist = box.getCenter(new THREE.Vector3()).distanceTo(inputCam.position);
    inputProjection(inputCam, Math.max(dist - 4 * size, dist / 1000), dist + 20 * size);
    // In the free view, the input camera's frustum up to the animal shows where the video was filmed from.
    const proxy = new THREE.PerspectiveCamera();
    proxy.matrixAutoUpdate = false;
    proxy.matrix.copy(c2w);
    proxy.updateMatrixWorld(true);
    inputProjection(proxy, dist / 20, dist);
    frustum = new THREE.CameraHelper(proxy);
    frustum.setColors(new THREE.Color(0xffaa33), new THREE.Color(0xffaa33), new THREE.Color(0xffaa33),
                      new THREE.Color(0xffdd88), new THREE.Color(0x888888));
    frustum.update();
    frustum.visible = false;
    scene.add(frustum);
    syncFreeToInput();
    resize();
  }).catch(function (err) { ZV.fail("could not read the fit's GLB: " + err); });
  requestAnimationFrame(tick);

  // --- tables -------------------------------------------------------------------------------
  function fillMetrics() {
    const M = R.metrics || {};
    const gt = "the benchmark video's ground truth (" + (R.video || R.source) + ")";
    const rows = [
      ["mask IoU", M.mask_iou, M.mask_iou_measured || "exported mesh against the fitted masks"],
      ["mask IoU (model)", M.mask_iou_model, "the optimised model's silhouettes at the fit resolution, against the same masks"],
      ["novel-view IoU", M.novel_view_iou, "silhouettes from cameras the fit never saw, against " + gt],
      ["mIoU (3D)", M.miou, "32\u00b3 voxel IoU after the scale line search, against " + gt],
      ["Chamfer (3D)", M.mcham, "surface Chamfer distance / ground-truth size, against " + gt],
      ["joints CD-J2J", M.joint, "joint-position Chamfer distance / ground-truth size, against " + gt],
      ["skinning IoU", M.skinning, "matched per-joint vertex sets, against " + gt],
      ["re-animation", M.reanimation, "Chamfer distance after re-posing to a held-out pose, against " + gt],
    ].filter(function (r) { return r[1] !== undefined && r[1] !== null; });
    const ious = D.silhouette_iou.filter(function (x) { return x !== null; });
    if (ious.length) {
      const mean = ious.reduce(function (a, b) { return a + b; }, 0) / ious.length;
      rows.push(["silhouette IoU (shown)", mean, "the magenta outline beside (this page's reprojection of the GLB) against the cyan masks, mean over " + ious.length + " frames"]);
    }
    const t = $("metrics");
    t.appendChild(ZV.el("tr", {}, [ZV.el("th", { text: "metric" }), ZV.el("th", { text: "value" }), ZV.el("th", { text: "measured against" })]));
    rows.forEach(function (r) {
      t.appendChild(ZV.el("tr", {}, [ZV.el("td", { text: r[0] }), ZV.el("td", { class: "num", text: ZV.fmt(r[1]) }), ZV.el("td", { text: r[2] })]));
    });
    if (!rows.length) t.appendChild(ZV.el("tr", {}, [ZV.el("td", { text: "no metrics in the record" })]));
  }

  function fillRetrieval() {
    const cands = R.retrieval || [];
    $("template").textContent = cands.length
      ? "Template " + R.template + ", chosen from " + cands.length + " retrieved candidates, ranked by retrieval's score (the embedders' distances fused; lower ranks first) and tried by a short trial fit each (trial IoU: its mask IoU, the best goes on)."
      : "Template " + R.template + " was given (--template): no retrieval ran.";
    if (!cands.length) return;
    const t = $("retrieval");
    t.appendChild(ZV.el("tr", {}, [ZV.el("th", { text: "candidate" }), ZV.el("th", { text: "score" }),
      ZV.el("th", { text: "trial IoU" }), ZV.el("th", { text: "embedder distances" })]));
    cands.forEach(function (c) {
      const dist = Object.keys(c.distances || {}).map(function (k) { return k + " " + ZV.fmt(c.distances[k]); }).join(", ");
      t.appendChild(ZV.el("tr", { class: c.name === R.template ? "chosen" : "" }, [
        ZV.el("td", { text: c.name + (c.name === R.template ? " (chosen)" : "") }),
        ZV.el("td", { class: "num", text: ZV.fmt(c.score) }),
        ZV.el("td", { class: "num", text: ZV.fmt(c.trial_iou) }),
        ZV.el("td", { class: "small", text: dist }),
      ]));
    });
  }

  function fillNotes() {
    const notes = (R.notes || []).slice();
    if (R.mask_source) notes.push("mask source: " + R.mask_source + (R.stored_video ? " (stored video " + R.stored_video + ")" : ""));
    if (!notes.length) notes.push("none");
    notes.forEach(function (n) { $("notes").appendChild(ZV.el("li", { text: n })); });
  }
})();
