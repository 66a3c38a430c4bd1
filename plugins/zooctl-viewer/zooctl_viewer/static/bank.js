// The bank gallery: a turntable per asset, filters, and an asset's GLB with its clips on click.
"use strict";
(function () {
  const D = window.ZOOCTL_VIEW;
  if (!D || D.kind !== "bank") { ZV.fail("data.js is missing or is not a bank gallery's data"); return; }
  const $ = function (id) { return document.getElementById(id); };
  const assets = D.assets;
  const activeTags = new Set();
  document.documentElement.style.setProperty("--views", String(D.turn_views));

  // --- filters ------------------------------------------------------------------------------
  function options(select, values) {
    Array.from(new Set(values.filter(Boolean))).sort().forEach(function (v) {
      select.appendChild(ZV.el("option", { value: v, text: v }));
    });
  }
  options($("body-plan"), assets.map(function (a) { return a.body_plan; }));
  options($("label"), assets.map(function (a) { return a.label; }));
  const allTags = Array.from(new Set([].concat.apply([], assets.map(function (a) { return a.tags; })))).sort();
  allTags.forEach(function (t) {
    const chip = ZV.el("span", { class: "tag chip", text: t, "data-tag": t });
    chip.addEventListener("click", function () {
      if (activeTags.has(t)) activeTags.delete(t); else activeTags.add(t);
      chip.classList.toggle("on", activeTags.has(t));
      apply();
    });
    $("tag-chips").appendChild(chip);
  });

  function matches(a) {
    const q = $("search").value.trim().toLowerCase();
    const text = [a.name, a.label || "", a.body_plan || ""].concat(a.tags).join(" ").toLowerCase();
    if (q && q.split(/\s+/).some(function (w) { return text.indexOf(w) < 0; })) return false;
    if ($("body-plan").value && a.body_plan !== $("body-plan").value) return false;
    if ($("label").value && a.label !== $("label").value) return false;
    for (const t of activeTags) if (a.tags.indexOf(t) < 0) return false;
    return true;
  }

  const tiles = assets.map(function (a) {
    const img = ZV.el("img", { src: a.turntable, alt: a.name + " turntable", loading: "lazy", decoding: "async" });
    const clips = Object.keys(a.clips || {});
    const tile = ZV.el("div", { class: "tile", title: a.source || "" }, [
      ZV.el("div", { class: "turn" }, [img]),
      ZV.el("div", { class: "name", text: a.name }),
      ZV.el("div", { class: "meta", text: [a.label, a.body_plan, clips.length + " clip" + (clips.length === 1 ? "" : "s")].filter(Boolean).join(" \u00b7 ") }),
      ZV.el("div", {}, a.tags.map(function (t) { return ZV.el("span", { class: "tag", text: t }); })),
    ]);
    tile.addEventListener("click", function () { open(a, tile); });
    $("gallery").appendChild(tile);
    return { asset: a, tile: tile, img: img };
  });

  function apply() {
    let shown = 0;
    tiles.forEach(function (t) { const on = matches(t.asset); t.tile.hidden = !on; if (on) shown++; });
    $("count").textContent = shown + " of " + assets.length + " assets" +
      (D.tags_required.length ? " tagged " + D.tags_required.join(", ") : "");
  }
  ["search", "body-plan", "label"].forEach(function (id) { $(id).addEventListener("input", apply); });
  $("turn-all").addEventListener("change", function (e) { document.body.classList.toggle("turn-all", e.target.checked); });
  apply();

  // For tests and the benchmark: the tiles on screen have their turntables decoded.
  (function markReady() {
    const visible = tiles.filter(function (t) {
      const r = t.tile.getBoundingClientRect();
      return !t.tile.hidden && r.top < window.innerHeight && r.bottom > 0;
    });
    Promise.all(visible.map(function (t) { return t.img.decode().catch(function () {}); })).then(function () {
      window.ZOOCTL_FIRST_FRAME_MS = performance.now();
      document.body.dataset.ready = "1";
    });
  })();

  // --- one asset in 3D ----------------------------------------------------------------------
  let renderer = null, scene, camera, controls, model = null, mixer = null, action = null, skeleton = null;
  let playing = true, last = 0, current = null, selectedTile = null;
  const glbs = {};
  window.ZOOCTL_ASSET = function (key, b64) { if (glbs[key]) glbs[key](b64); };

  function loadScript(a) {
    return new Promise(function (resolve, reject) {
      glbs[a.key] = resolve;
      const s = ZV.el("script", { src: a.glb });
      s.onerror = function () { reject(new Error("cannot load " + a.glb)); };
      document.body.appendChild(s);
    });
  }

  function setup3d() {
    renderer = ZV.makeRenderer($("canvas3d"));
    scene = new THREE.Scene();
    scene.background = new THREE.Color(0x2a2f36);
    ZV.addLights(scene);
    camera = new THREE.PerspectiveCamera(30, 16 / 6, 0.01, 1000);
    controls = new THREE.OrbitControls(camera, $("canvas3d"));
    new ResizeObserver(function () {
      const r = $("stage3d").getBoundingClientRect();
      renderer.setSize(Math.max(1, Math.round(r.width)), Math.max(1, Math.round(r.height)), false);
      camera.aspect = r.width / Math.max(1, r.height);
      camera.updateProjectionMatrix();
    }).observe($("stage3d"));
    requestAnimationFrame(tick);
  }

  function tick(now) {
    const dt = last ? (now - last) / 1000 : 0;
    last = now;
    if (mixer && playing) mixer.update(dt);
    if (model) renderer.render(scene, camera);
    requestAnimationFrame(tick);
  }

  function open(a, tile) {
    if (selectedTile) selectedTile.classList.remove("selected");
    selectedTile = tile; tile.classList.add("selected");
    $("asset-panel").hidden = false;
    $("asset-name").textContent = a.name + (a.label ? " (" + a.label + ")" : "");
    $("asset-info").textContent = [a.vertices + " vertices", a.joints + " joints", a.body_plan ? "body plan " + a.body_plan : null,
      "licence " + a.license, a.source].filter(Boolean).join(" \u00b7 ");
    if (!renderer) setup3d();
    current = a.key;
    $("asset-panel").scrollIntoView({ block: "nearest" });
    loadScript(a).then(ZV.parseGLB).then(function (gltf) {
      if (current !== a.key) return;
      if (model) { scene.remove(model); scene.remove(skeleton); }
      model = gltf.scene;
      ZV.prepareModel(model);
      scene.add(model);
      skeleton = new THREE.SkeletonHelper(model);
      skeleton.visible = $("skeleton").checked;
      scene.add(skeleton);
      mixer = new THREE.AnimationMixer(model);
      const select = $("clip");
      select.innerHTML = "";
      gltf.animations.forEach(function (c, i) { select.appendChild(ZV.el("option", { value: String(i), text: c.name + " (" + ZV.fmt(c.duration, 2) + " s)" })); });
      if (!gltf.animations.length) select.appendChild(ZV.el("option", { value: "", text: "rest pose (no clips)" }));
      select.onchange = function () { play(gltf.animations[+select.value]); };
      play(gltf.animations[0]);
      frame();
      document.body.dataset.asset = a.name;
    }).catch(function (err) { ZV.fail("could not open " + a.name + ": " + err); });
  }

  function play(clip) {
    if (action) action.stop();
    action = clip ? mixer.clipAction(clip) : null;
    if (action) action.play();
  }

  function frame() {
    const box = ZV.posedBox(model);
    const c = box.getCenter(new THREE.Vector3());
    const r = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-3);
    const d = r / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)) * 1.1;
    camera.position.set(c.x + d * 0.8, c.y + d * 0.3, c.z + d * 0.5);
    camera.near = d / 100; camera.far = d * 100;
    camera.updateProjectionMatrix();
    controls.target.copy(c);
    controls.update();
  }

  $("play").addEventListener("click", function () { playing = !playing; $("play").textContent = playing ? "Pause" : "Play"; });
  $("skeleton").addEventListener("change", function (e) { if (skeleton) skeleton.visible = e.target.checked; });
  $("close").addEventListener("click", function () {
    $("asset-panel").hidden = true; current = null;
    if (selectedTile) selectedTile.classList.remove("selected");
  });
})();
