// rce annotate: click the nodes of a branch on the first frame of a video.
// Image coordinates are pixels with pixel centres at integers (OpenCV), x right, y down.
"use strict";
(() => {
  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const statusEl = document.getElementById("status");
  const nextEl = document.getElementById("next-command");
  const slider = document.getElementById("frame");
  const frameLabel = document.getElementById("frame-label");
  const snapBox = document.getElementById("snap");

  const HIT_PX = 9;        // screen pixels within which a press grabs a node
  const DRAG_PX = 4;       // screen pixels a press must move to become a drag
  let info = null;
  let image = new Image();
  let frameShown = -1;     // index of the frame on screen
  let view = { scale: 1, ox: 0, oy: 0 };
  let points = [];         // [[x, y], ...] image px; id = index, 0 = root
  let parent = [];         // parent[i] (null for the root)
  let selected = null;     // node new clicks attach to
  const undoStack = [];
  let pending = 0;         // snap requests in flight
  let press = null;        // current pointer interaction

  // ---------------------------------------------------------------- coordinates
  const toCanvas = (x, y) => [view.ox + (x + 0.5) * view.scale, view.oy + (y + 0.5) * view.scale];
  const toImage = (cx, cy) => [(cx - view.ox) / view.scale - 0.5, (cy - view.oy) / view.scale - 0.5];
  function eventCanvasXY(ev) {
    const r = canvas.getBoundingClientRect();
    return [ev.clientX - r.left, ev.clientY - r.top];
  }
  function fit() {
    if (!info) return;
    const s = Math.min(canvas.width / info.width, canvas.height / info.height);
    view = { scale: s, ox: (canvas.width - info.width * s) / 2, oy: (canvas.height - info.height * s) / 2 };
    draw();
  }
  function zoomAt(factor, cx, cy) {
    const [x, y] = toImage(cx, cy);
    view.scale = Math.min(40, Math.max(0.1, view.scale * factor));
    view.ox = cx - (x + 0.5) * view.scale;
    view.oy = cy - (y + 0.5) * view.scale;
    draw();
  }
  function resize() {
    canvas.width = canvas.clientWidth;
    canvas.height = canvas.clientHeight;
    fit();
  }

  // ---------------------------------------------------------------- state
  const snapshot = () => JSON.stringify({ points, parent, selected });
  function pushUndo() { undoStack.push(snapshot()); }
  function undo() {
    if (!undoStack.length) { say("nothing to undo"); return; }
    ({ points, parent, selected } = JSON.parse(undoStack.pop()));
    draw(); say(summary());
  }
  const edges = () => parent.map((p, i) => [p, i]).filter(e => e[0] !== null);
  const children = i => parent.reduce((a, p, j) => (p === i ? a.concat(j) : a), []);
  function summary() {
    const n = points.length, tips = points.filter((_, i) => !children(i).length).length;
    let s = `${n} node${n === 1 ? "" : "s"}, ${edges().length} edge${edges().length === 1 ? "" : "s"}`;
    if (n > 1) s += `, ${tips} tip${tips === 1 ? "" : "s"}`;
    if (selected !== null) s += ` — next click adds a child of node ${selected}`;
    else s += " — click the root of the branch";
    return s;
  }
  function say(text, isError = false) {
    statusEl.textContent = text;
    statusEl.classList.toggle("error", isError);
  }
  function nodeAt(cx, cy) {
    let best = null, bestD = HIT_PX;
    points.forEach(([x, y], i) => {
      const [px, py] = toCanvas(x, y);
      const d = Math.hypot(px - cx, py - cy);
      if (d <= bestD) { best = i; bestD = d; }
    });
    return best;
  }

  async function post(url, body) {
    const r = await fetch(url, { method: "POST", headers: { "Content-Type": "application/json" },
                                 body: JSON.stringify(body) });
    const out = await r.json();
    if (!r.ok) throw new Error(out.error || r.statusText);
    return out;
  }
  async function snapped(x, y) {
    if (!snapBox.checked) return [x, y];
    pending++;
    try {
      const s = await post("/api/snap", { x, y });
      return [s.x, s.y];
    } catch (e) {
      say(`snap failed: ${e.message}`, true);
      return [x, y];
    } finally { pending--; }
  }
  const inImage = (x, y) => x >= -0.5 && y >= -0.5 && x <= info.width - 0.5 && y <= info.height - 0.5;
  const editable = () => {
    if (frameShown === 0) return true;
    say("nodes are placed on frame 0, where tracking starts: move the slider back to 0 to edit", true);
    return false;
  };

  async function addNode(x, y) {
    if (!inImage(x, y)) { say("that click is outside the frame", true); return; }
    const [sx, sy] = await snapped(x, y);
    pushUndo();
    points.push([sx, sy]);
    parent.push(points.length === 1 ? null : selected);
    selected = points.length - 1;
    draw(); say(summary());
  }
  async function moveNode(i, x, y, before) {
    const [sx, sy] = await snapped(x, y);
    undoStack.push(before);
    points[i] = [sx, sy];
    draw(); say(summary());
  }

  // ---------------------------------------------------------------- drawing
  const ZONE = ["#2166ac", "#1b9e77", "#b2182b"];
  function draw() {
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#202124";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (!info) return;
    ctx.imageSmoothingEnabled = view.scale < 2;
    if (image.complete && image.naturalWidth)
      ctx.drawImage(image, view.ox, view.oy, info.width * view.scale, info.height * view.scale);
    const alpha = frameShown === 0 ? 1 : 0.45;   // on other frames the nodes are only a reference
    ctx.globalAlpha = alpha;
    ctx.lineWidth = 2;
    ctx.strokeStyle = "#fdd835";
    for (const [p, c] of edges()) {
      const [ax, ay] = toCanvas(...points[p]), [bx, by] = toCanvas(...points[c]);
      ctx.beginPath(); ctx.moveTo(ax, ay); ctx.lineTo(bx, by); ctx.stroke();
    }
    ctx.font = "12px system-ui, sans-serif";
    points.forEach(([x, y], i) => {
      const [cx, cy] = toCanvas(x, y);
      const depth = (() => { let d = 0, j = i; while (parent[j] !== null && parent[j] !== undefined) { j = parent[j]; d++; } return d; })();
      ctx.fillStyle = i === 0 ? "#ffffff" : ZONE[Math.min(2, Math.floor(3 * depth / Math.max(1, points.length)))];
      ctx.beginPath(); ctx.arc(cx, cy, 4, 0, 2 * Math.PI); ctx.fill();
      ctx.strokeStyle = "#000"; ctx.lineWidth = 1; ctx.stroke();
      if (i === selected) {
        ctx.strokeStyle = "#fdd835"; ctx.lineWidth = 2;
        ctx.beginPath(); ctx.arc(cx, cy, 8, 0, 2 * Math.PI); ctx.stroke();
      }
      ctx.fillStyle = "#fff"; ctx.strokeStyle = "#000"; ctx.lineWidth = 3;
      ctx.strokeText(String(i), cx + 7, cy - 7); ctx.fillText(String(i), cx + 7, cy - 7);
    });
    ctx.globalAlpha = 1;
  }

  // ---------------------------------------------------------------- frames
  function showFrame(i) {
    const img = new Image();
    img.onload = () => { image = img; frameShown = i; frameLabel.textContent = String(i); draw(); };
    img.onerror = () => say(`cannot load frame ${i}`, true);
    img.src = `/frame/${i}.jpg`;
  }

  // ---------------------------------------------------------------- pointer
  canvas.addEventListener("pointerdown", ev => {
    if (!info || ev.button !== 0) return;
    canvas.setPointerCapture(ev.pointerId);
    const [cx, cy] = eventCanvasXY(ev);
    press = { cx, cy, node: nodeAt(cx, cy), moved: false, view: { ...view }, before: snapshot() };
  });
  canvas.addEventListener("pointermove", ev => {
    if (!press) return;
    const [cx, cy] = eventCanvasXY(ev);
    if (!press.moved && Math.hypot(cx - press.cx, cy - press.cy) < DRAG_PX) return;
    if (!press.moved && press.node !== null && !editable()) { press.node = null; }
    press.moved = true;
    if (press.node !== null) {
      points[press.node] = toImage(cx, cy);
    } else {
      view.ox = press.view.ox + (cx - press.cx);
      view.oy = press.view.oy + (cy - press.cy);
    }
    draw();
  });
  canvas.addEventListener("pointerup", ev => {
    if (!press) return;
    const p = press; press = null;
    const [cx, cy] = eventCanvasXY(ev);
    if (p.moved) {
      if (p.node !== null) moveNode(p.node, ...toImage(cx, cy), p.before);
      return;
    }
    if (!editable()) return;
    if (p.node !== null) {
      selected = p.node;
      draw();
      say(children(p.node).length ? `node ${p.node} selected: the next click starts a side branch from it`
                                   : summary());
      return;
    }
    addNode(...toImage(cx, cy));
  });
  canvas.addEventListener("wheel", ev => {
    ev.preventDefault();
    const [cx, cy] = eventCanvasXY(ev);
    zoomAt(ev.deltaY < 0 ? 1.25 : 0.8, cx, cy);
  }, { passive: false });
  document.addEventListener("keydown", ev => {
    if ((ev.ctrlKey || ev.metaKey) && ev.key === "z") { ev.preventDefault(); undo(); }
    else if (ev.key === "+" || ev.key === "=") zoomAt(1.25, canvas.width / 2, canvas.height / 2);
    else if (ev.key === "-") zoomAt(0.8, canvas.width / 2, canvas.height / 2);
    else if (ev.key === "0") fit();
  });

  // ---------------------------------------------------------------- buttons
  document.getElementById("undo").onclick = undo;
  document.getElementById("zoom-in").onclick = () => zoomAt(1.25, canvas.width / 2, canvas.height / 2);
  document.getElementById("zoom-out").onclick = () => zoomAt(0.8, canvas.width / 2, canvas.height / 2);
  document.getElementById("zoom-fit").onclick = fit;
  slider.oninput = () => showFrame(Number(slider.value));
  async function save() {
    try {
      const out = await post("/api/save", { points, edges: edges(), root: 0 });
      say(`wrote ${out.annotations} and ${out.graph} (${out.n_nodes} nodes, ${out.n_bends} bends)`);
      nextEl.hidden = false;
      nextEl.textContent = `Next:\n${out.next}`;
      return true;
    } catch (e) {
      say(`not saved: ${e.message}`, true);
      return false;
    }
  }
  document.getElementById("save").onclick = save;
  document.getElementById("finish").onclick = async () => {
    if (!(await save())) return;
    await post("/api/quit", {});
    say(statusEl.textContent + " — session finished; you can close this tab");
    for (const b of document.querySelectorAll("button, input")) b.disabled = true;
  };

  // ---------------------------------------------------------------- start
  window.addEventListener("resize", resize);
  fetch("/api/info").then(r => r.json()).then(i => {
    info = i;
    document.getElementById("title").textContent = `rce annotate — ${i.video} (${i.width}×${i.height}, ${i.n_frames} frames)`;
    document.title = `rce annotate — ${i.video}`;
    slider.max = String(Math.max(0, i.n_frames - 1));
    if (i.previous) {
      points = i.previous.points;
      parent = points.map(() => null);
      for (const [p, c] of i.previous.edges) parent[c] = p;
      selected = points.length - 1;
    }
    resize();
    showFrame(0);
    say(summary());
  }).catch(e => say(`cannot reach the rce annotate server: ${e.message}`, true));

  // for tests and scripting: read-only views of the state and the coordinate transform
  window.rce = {
    get ready() { return info !== null && frameShown >= 0; },
    get pending() { return pending; },
    get frameShown() { return frameShown; },
    state: () => ({ points: points.map(p => p.slice()), edges: edges(), selected }),
    toClient: (x, y) => {
      const r = canvas.getBoundingClientRect();
      const [cx, cy] = toCanvas(x, y);
      return [r.left + cx, r.top + cy];
    },
  };
})();
