// The benchmark table: one row per fit of `zooctl bench run DIR`, each opening its fit's page.
"use strict";
(function () {
  const D = window.ZOOCTL_VIEW;
  if (!D || D.kind !== "bench") { ZV.fail("data.js is missing or is not a benchmark's data"); return; }
  const $ = function (id) { return document.getElementById(id); };
  // Which way is better, from CASA's metrics (zooctl/fit/metrics.py): IoUs up, distances down.
  const HIGHER = { mask_iou: true, novel_view_iou: true, miou: true, skinning: true };
  const LABELS = { mask_iou: "mask IoU", novel_view_iou: "novel-view IoU", miou: "mIoU", mcham: "Chamfer",
                   joint: "CD-J2J", skinning: "skinning IoU", reanimation: "re-animation", wall_s: "wall s" };
  const cols = ["video", "ablation", "template"].concat(D.columns).concat(["wall_s"]);
  const numeric = function (c) { return D.columns.indexOf(c) >= 0 || c === "wall_s"; };
  let sortBy = "video", ascending = true;
  $("subtitle").textContent = D.rows.length + " fits of the videos in " + D.folder;

  function header(table, names, sortable) {
    table.appendChild(ZV.el("tr", {}, names.map(function (c) {
      const arrow = numeric(c) && c !== "wall_s" ? (HIGHER[c] ? " \u2191" : " \u2193") : "";
      const th = ZV.el("th", { text: (LABELS[c] || c) + arrow + (sortable && c === sortBy ? (ascending ? " \u25b4" : " \u25be") : "") });
      if (sortable) {
        th.style.cursor = "pointer";
        th.addEventListener("click", function () { ascending = sortBy === c ? !ascending : true; sortBy = c; table_(); });
      }
      return th;
    })));
  }

  function table_() {
    const t = $("rows");
    t.innerHTML = "";
    header(t, cols, true);
    const rows = D.rows.slice().sort(function (a, b) {
      const x = a[sortBy], y = b[sortBy];
      if (x === y) return 0;
      if (x === null || x === undefined) return 1;
      if (y === null || y === undefined) return -1;
      return (x < y ? -1 : 1) * (ascending ? 1 : -1);
    });
    rows.forEach(function (r) {
      const tr = ZV.el("tr", { class: "link" }, cols.map(function (c) {
        return ZV.el("td", { class: numeric(c) ? "num" : "", text: numeric(c) ? ZV.fmt(r[c], c === "wall_s" ? 0 : 3) : String(r[c]) });
      }));
      tr.addEventListener("click", function () { window.location.href = r.page; });
      tr.title = "open fit " + r.fit;
      t.appendChild(tr);
    });
  }

  function summary() {
    const t = $("summary");
    const abl = Array.from(new Set(D.rows.map(function (r) { return r.ablation; })));
    header(t, ["ablation", "fits"].concat(D.columns), false);
    abl.forEach(function (a) {
      const rs = D.rows.filter(function (r) { return r.ablation === a; });
      t.appendChild(ZV.el("tr", {}, [ZV.el("td", { text: a }), ZV.el("td", { class: "num", text: String(rs.length) })].concat(
        D.columns.map(function (c) {
          const v = rs.map(function (r) { return r[c]; }).filter(function (x) { return x !== null && x !== undefined; });
          return ZV.el("td", { class: "num", text: v.length ? ZV.fmt(v.reduce(function (p, q) { return p + q; }, 0) / v.length) : "n/a" });
        }))));
    });
  }

  summary();
  table_();
  window.ZOOCTL_FIRST_FRAME_MS = performance.now();
  document.body.dataset.ready = "1";
})();
