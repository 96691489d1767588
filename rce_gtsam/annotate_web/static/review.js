// rce review: scrub a video with its tracks, drag wrong nodes into place, re-track, save.
// Image coordinates are pixels with pixel centres at integers (OpenCV), x right, y down.
"use strict";
(() => {
  const $ = id => document.getElementById(id);
  const canvas = $("view"), ctx = canvas.getContext("2d");
  const slider = $("frame"), frameLabel = $("frame-label"), timeline = $("timeline");
  const statusEl = $("status"), nextEl = $("next-command");

  const HIT_PX = 10;       // screen pixels within which a press grabs a node
  const DRAG_PX = 3;       // screen pixels a press must move to become a drag
  const TRAIL = 15;        // frames of the selected node's path drawn either side
  const PALETTE = ["#4fc3f7", "#81c784", "#ffb74d", "#e57373", "#ba68c8", "#4db6ac", "#fff176", "#90a4ae",
                   "#f06292", "#aed581", "#7986cb", "#ffd54f"];
  let info = null, tracks = null;
  let frame = 0, frameShown = -1, image = null;
  const images = new Map();                 // frame -> loaded Image (a small cache)
  let view = { scale: 1, ox: 0, oy: 0 };
  let corrections = new Map();              // "frame:node" -> {frame, node, x, y}
  let retrackedKey = "";                    // corrections the shown tracks were re-tracked from
  const undoStack = [];
  let selected = null, press = null, pending = 0, playing = null;
  let flagFrames = [];                      // start frames of the flagged runs

  // ---------------------------------------------------------------- coordinates
  const toCanvas = (x, y) => [view.ox + (x + 0.5) * view.scale, view.oy + (y + 0.5) * view.scale];
  const toImage = (cx, cy) => [(cx - view.ox) / view.scale - 0.5, (cy - view.oy) / view.scale - 0.5];
  const eventXY = ev => { const r = canvas.getBoundingClientRect(); return [ev.clientX - r.left, ev.clientY - r.top]; };
  function fit() {
    if (!info) return;
    const s = Math.min(canvas.width / info.width, canvas.height / info.height);
    view = { scale: s, ox: (canvas.width - info.width * s) / 2, oy: (canvas.height - info.height * s) / 2 };
    draw();
  }
  function zoomAt(f, cx, cy) {
    const [x, y] = toImage(cx, cy);
    view.scale = Math.min(40, Math.max(0.1, view.scale * f));
    view.ox = cx - (x + 0.5) * view.scale; view.oy = cy - (y + 0.5) * view.scale;
    draw();
  }
  function resize() {
    canvas.width = canvas.clientWidth; canvas.height = canvas.clientHeight;
    timeline.width = timeline.clientWidth; timeline.height = timeline.clientHeight;
    fit(); drawTimeline();
  }

  // ---------------------------------------------------------------- state
  const key = (f, n) => `${f}:${n}`;
  const corrList = () => [...corrections.values()].sort((a, b) => a.frame - b.frame || a.node - b.node);
  const corrKey = () => JSON.stringify(corrList());
  const stale = () => corrKey() !== retrackedKey;
  const nodeIndex = n => info.nodes.indexOf(n);
  function position(i, f) {
    // [x, y, kind]: kind "corr" (a correction here), "vis", "lost" (the tracker's guess), "missing" (no row in this
    // frame: drawn where the nearest frame with a row has it, so that it can be dragged into place); null: no row at all
    const c = corrections.get(key(f, info.nodes[i]));
    if (c) return [c.x, c.y, "corr"];
    const p = tracks.xy[i][f];
    if (p) return [p[0], p[1], tracks.visible[i][f] ? "vis" : "lost"];
    for (let d = 1; d < info.n_frames; d++) {
      const q = tracks.xy[i][f - d] || tracks.xy[i][f + d];
      if (q) return [q[0], q[1], "missing"];
    }
    return null;
  }
  function say(text, cls = "") { statusEl.textContent = text; statusEl.className = cls; }
  function pushUndo() { undoStack.push(JSON.stringify(corrList())); }
  function undo() {
    if (!undoStack.length) { say("nothing to undo"); return; }
    corrections = new Map(JSON.parse(undoStack.pop()).map(c => [key(c.frame, c.node), c]));
    changed("undone");
  }
  function changed(what) {
    $("retrack").classList.toggle("stale", stale());
    renderCorrections(); drawTimeline(); draw();
    if (what) say(`${what} — ${corrections.size} correction${corrections.size === 1 ? "" : "s"}` +
                  (stale() ? "; press Re-track (R) to refit the tracks" : ""));
  }
  function nodeAt(cx, cy) {
    let best = null, bestD = HIT_PX;
    info.nodes.forEach((_, i) => {
      const p = position(i, frame);
      if (!p) return;
      const [px, py] = toCanvas(p[0], p[1]);
      const d = Math.hypot(px - cx, py - cy);
      if (d <= bestD) { best = i; bestD = d; }
    });
    return best;
  }

  // ---------------------------------------------------------------- drawing
  const colour = i => PALETTE[i % PALETTE.length];
  function draw() {
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#202124"; ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (!info) return;
    ctx.imageSmoothingEnabled = view.scale < 2;
    if (image) ctx.drawImage(image, view.ox, view.oy, info.width * view.scale, info.height * view.scale);
    if (!tracks) return;
    const pos = info.nodes.map((_, i) => position(i, frame));
    // graph edges
    ctx.lineWidth = 2; ctx.strokeStyle = "rgba(253, 216, 53, 0.75)";
    for (const [a, b] of info.edges) {
      const pa = pos[nodeIndex(a)], pb = pos[nodeIndex(b)];
      if (!pa || !pb) continue;
      ctx.setLineDash(pa[2] === "lost" || pb[2] === "lost" || pa[2] === "missing" || pb[2] === "missing" ? [5, 4] : []);
      ctx.beginPath(); ctx.moveTo(...toCanvas(pa[0], pa[1])); ctx.lineTo(...toCanvas(pb[0], pb[1])); ctx.stroke();
    }
    ctx.setLineDash([]);
    // the selected node's path, +-TRAIL frames
    if (selected !== null) {
      ctx.strokeStyle = "rgba(255, 255, 255, 0.8)"; ctx.lineWidth = 1.5; ctx.setLineDash([4, 3]);
      ctx.beginPath();
      let started = false;
      for (let f = Math.max(0, frame - TRAIL); f <= Math.min(info.n_frames - 1, frame + TRAIL); f++) {
        const p = position(selected, f);
        if (!p) { started = false; continue; }
        const [cx, cy] = toCanvas(p[0], p[1]);
        if (started) ctx.lineTo(cx, cy); else ctx.moveTo(cx, cy);
        started = true;
      }
      ctx.stroke(); ctx.setLineDash([]);
    }
    ctx.font = "bold 12px system-ui, sans-serif";
    pos.forEach((p, i) => {
      if (!p) return;
      const [cx, cy] = toCanvas(p[0], p[1]);
      const col = colour(i);
      const s = info.has_sigma && tracks.sigma && tracks.sigma[i][frame];
      if (p[2] === "corr") {
        ctx.fillStyle = "#ff4fd8"; ctx.strokeStyle = "#fff"; ctx.lineWidth = 1.5;
        ctx.beginPath(); ctx.moveTo(cx, cy - 7); ctx.lineTo(cx + 7, cy); ctx.lineTo(cx, cy + 7); ctx.lineTo(cx - 7, cy);
        ctx.closePath(); ctx.fill(); ctx.stroke();
      } else if (p[2] === "lost" || p[2] === "missing") {
        ctx.strokeStyle = "#bdc1c6"; ctx.lineWidth = 1.5; ctx.setLineDash([3, 3]);
        ctx.beginPath(); ctx.arc(cx, cy, Math.max(6, s ? 2 * s * view.scale : 0), 0, 2 * Math.PI); ctx.stroke();
        ctx.setLineDash([]);
        ctx.beginPath(); ctx.moveTo(cx - 3, cy - 3); ctx.lineTo(cx + 3, cy + 3); ctx.moveTo(cx + 3, cy - 3);
        ctx.lineTo(cx - 3, cy + 3); ctx.stroke();
      } else {
        if (s && 2 * s * view.scale > 4) {  // the 2-sigma circle, where it is larger than the dot
          ctx.strokeStyle = col; ctx.globalAlpha = 0.9; ctx.lineWidth = 1.5;
          ctx.beginPath(); ctx.arc(cx, cy, 2 * s * view.scale, 0, 2 * Math.PI); ctx.stroke();
          ctx.globalAlpha = 1;
        }
        ctx.fillStyle = col; ctx.strokeStyle = "#000"; ctx.lineWidth = 1;
        ctx.beginPath(); ctx.arc(cx, cy, 3, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
      }
      if (i === selected) {
        ctx.strokeStyle = "#fff"; ctx.lineWidth = 2;
        ctx.beginPath(); ctx.arc(cx, cy, 11, 0, 2 * Math.PI); ctx.stroke();
      }
      ctx.fillStyle = "#fff"; ctx.strokeStyle = "#000"; ctx.lineWidth = 3;
      const label = String(info.nodes[i]);
      ctx.strokeText(label, cx + 8, cy - 8); ctx.fillText(label, cx + 8, cy - 8);
    });
  }
  function drawTimeline() {
    if (!info) return;
    const t = timeline.getContext("2d"), w = timeline.width, h = timeline.height, n = info.n_frames;
    t.clearRect(0, 0, w, h);
    t.fillStyle = "#3c4043"; t.fillRect(0, 0, w, h);
    const x = f => (n <= 1 ? 0 : f / (n - 1)) * (w - 1);
    t.fillStyle = "#ea4335";
    for (const r of (tracks ? tracks.flags : [])) t.fillRect(x(r.start), 0, Math.max(1.5, x(r.end + 1) - x(r.start)), h);
    t.fillStyle = "#ff4fd8";
    for (const c of corrections.values()) t.fillRect(x(c.frame) - 1, 0, 3, h);
    t.fillStyle = "#fff"; t.fillRect(x(frame) - 0.5, 0, 1.5, h);
  }

  // ---------------------------------------------------------------- lists
  function describe(r) {
    const parts = [];
    const names = { lost: "lost", sigma: "large σ", jump: "jump" };
    for (const k of ["lost", "sigma", "jump"]) if (r.nodes[k].length) parts.push(`${names[k]}: ${r.nodes[k].join(", ")}`);
    return parts.join(" · ");
  }
  function renderFlags() {
    const ol = $("flags");
    ol.replaceChildren();
    flagFrames = tracks.flags.map(r => r.start);
    const nf = tracks.flags.reduce((s, r) => s + r.end - r.start + 1, 0);
    $("flag-count").textContent = `${tracks.flags.length} run${tracks.flags.length === 1 ? "" : "s"}, ${nf} frames`;
    for (const r of tracks.flags) {
      const li = document.createElement("li");
      li.dataset.start = r.start; li.dataset.end = r.end;
      li.innerHTML = `<span class="fr"></span><span class="why"></span>`;
      li.querySelector(".fr").textContent = r.end > r.start ? `${r.start}–${r.end}` : `${r.start}`;
      li.querySelector(".why").textContent = describe(r);
      li.onclick = () => showFrame(r.start);
      ol.append(li);
    }
    if (!tracks.flags.length) ol.innerHTML = `<li class="muted">none: every node visible, no large σ, no jump</li>`;
    highlight();
  }
  function renderCorrections() {
    const ol = $("corrections");
    ol.replaceChildren();
    $("corr-count").textContent = `${corrections.size}` + (corrections.size && stale() ? " (not re-tracked yet)" : "");
    for (const c of corrList()) {
      const li = document.createElement("li");
      li.dataset.frame = c.frame;
      li.innerHTML = `<span class="fr"></span><span class="why"></span><span class="del" title="drop this correction">✕</span>`;
      li.querySelector(".fr").textContent = `frame ${c.frame}`;
      li.querySelector(".why").textContent = `node ${c.node} → (${c.x.toFixed(1)}, ${c.y.toFixed(1)})`;
      li.onclick = ev => {
        if (ev.target.classList.contains("del")) { pushUndo(); corrections.delete(key(c.frame, c.node)); changed("correction dropped"); }
        else { selected = nodeIndex(c.node); showFrame(c.frame); }
      };
      ol.append(li);
    }
    if (!corrections.size) ol.innerHTML = `<li class="muted">drag a node to where it really is; in a frame you ` +
      `correct, correct every wrong node: the re-track starts from all nodes' positions there</li>`;
    highlight();
  }
  function highlight() {
    for (const li of document.querySelectorAll("#flags li[data-start]"))
      li.classList.toggle("here", frame >= Number(li.dataset.start) && frame <= Number(li.dataset.end));
    for (const li of document.querySelectorAll("#corrections li[data-frame]"))
      li.classList.toggle("here", frame === Number(li.dataset.frame));
  }

  // ---------------------------------------------------------------- frames
  function showFrame(f) {
    if (!info) return;
    f = Math.max(0, Math.min(info.n_frames - 1, Math.round(f)));
    frame = f; slider.value = String(f);
    frameLabel.textContent = `${f} / ${info.n_frames - 1}`;
    highlight(); drawTimeline();
    const cached = images.get(f);
    if (cached) { image = cached; frameShown = f; draw(); return; }
    draw();
    const img = new Image();
    img.onload = () => {
      images.set(f, img);
      if (images.size > 96) images.delete(images.keys().next().value);
      if (frame === f) { image = img; frameShown = f; draw(); }
    };
    img.onerror = () => say(`cannot load frame ${f}`, "error");
    img.src = `/frame/${f}.jpg`;
  }
  const jumpFlag = dir => {
    const cands = dir > 0 ? flagFrames.filter(s => s > frame) : flagFrames.filter(s => s < frame).reverse();
    if (cands.length) showFrame(cands[0]); else say(dir > 0 ? "no flagged frame after this one" : "no flagged frame before this one");
  };
  function togglePlay() {
    if (playing) { clearInterval(playing); playing = null; $("play").textContent = "▶"; return; }
    $("play").textContent = "❚❚";
    playing = setInterval(() => {
      if (frame >= info.n_frames - 1) { togglePlay(); return; }
      showFrame(frame + 1);
    }, 1000 / Math.min(30, info.fps || 30));
  }

  // ---------------------------------------------------------------- server
  async function post(url, body) {
    const r = await fetch(url, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
    const out = await r.json();
    if (!r.ok) throw new Error(out.error || r.statusText);
    return out;
  }
  function setTracks(t) { tracks = t; renderFlags(); drawTimeline(); draw(); }
  async function retrack() {
    if (pending) return false;
    pending++;
    const body = { corrections: corrList() }, k = corrKey();
    say(`re-tracking from ${corrections.size} correction${corrections.size === 1 ? "" : "s"}…`, "busy");
    for (const b of ["retrack", "save", "finish"]) $(b).disabled = true;
    try {
      const out = await post("/api/retrack", body);
      retrackedKey = k; setTracks(out);
      const nodes = new Set(body.corrections.map(c => c.node));
      say(`re-tracked ${nodes.size} node${nodes.size === 1 ? "" : "s"} from ${body.corrections.length} correction` +
          `${body.corrections.length === 1 ? "" : "s"}; largest change ${out.max_moved_px.toFixed(1)} px; ` +
          `${out.flags.length} flagged run${out.flags.length === 1 ? "" : "s"} — Save (Ctrl+S) writes them`);
      return true;
    } catch (e) { say(`re-track failed: ${e.message}`, "error"); return false; }
    finally { pending--; for (const b of ["retrack", "save", "finish"]) $(b).disabled = false; changed(); }
  }
  async function save() {
    if (pending) return false;
    pending++;
    say("saving…", "busy");
    const k = corrKey();
    try {
      const out = await post("/api/save", { corrections: corrList() });
      if (k !== retrackedKey) { retrackedKey = k; setTracks(await (await fetch("/api/tracks")).json()); }
      say(`wrote ${out.corrections} (${out.n_corrections} correction${out.n_corrections === 1 ? "" : "s"}) and ` +
          `${out.tracks} (the tracks before: ${out.backup})`);
      nextEl.hidden = false;
      nextEl.textContent = out.reproducible ? `Reproduce:\n${out.command}` :
        `Not reproducible from the video alone: the other nodes' rows are not what rce track's tracker gives with these ` +
        `options (another tracker, other options, or edits). This command re-tracks the same corrections over the ` +
        `tracker's own rows:\n${out.command}`;
      return true;
    } catch (e) { say(`not saved: ${e.message}`, "error"); return false; }
    finally { pending--; changed(); }
  }

  // ---------------------------------------------------------------- pointer
  canvas.addEventListener("pointerdown", ev => {
    if (!tracks || ev.button !== 0) return;
    canvas.setPointerCapture(ev.pointerId);
    canvas.focus();
    const [cx, cy] = eventXY(ev);
    press = { cx, cy, node: nodeAt(cx, cy), moved: false, view: { ...view } };
  });
  canvas.addEventListener("pointermove", ev => {
    if (!press) return;
    const [cx, cy] = eventXY(ev);
    if (!press.moved && Math.hypot(cx - press.cx, cy - press.cy) < DRAG_PX) return;
    if (!press.moved && press.node !== null) { pushUndo(); selected = press.node; }
    press.moved = true;
    if (press.node !== null) {
      const [x, y] = toImage(cx, cy), n = info.nodes[press.node];
      corrections.set(key(frame, n), { frame, node: n, x: clampX(x), y: clampY(y) });
    } else {
      view.ox = press.view.ox + (cx - press.cx); view.oy = press.view.oy + (cy - press.cy);
    }
    draw();
  });
  const round2 = v => Math.round(v * 100) / 100;
  const clampX = x => round2(Math.max(-0.5, Math.min(info.width - 0.5, x)));
  const clampY = y => round2(Math.max(-0.5, Math.min(info.height - 0.5, y)));
  canvas.addEventListener("pointerup", () => {
    if (!press) return;
    const p = press; press = null;
    if (p.moved && p.node !== null) {
      const c = corrections.get(key(frame, info.nodes[p.node]));
      changed(`node ${c.node} corrected in frame ${frame} to (${c.x.toFixed(1)}, ${c.y.toFixed(1)})`);
    } else if (!p.moved) {
      selected = p.node; draw();
      if (p.node !== null) {
        const q = position(p.node, frame), sg = tracks.sigma && tracks.sigma[p.node][frame];
        say(`node ${info.nodes[p.node]} in frame ${frame}: (${q[0].toFixed(1)}, ${q[1].toFixed(1)}) px` +
            (q[2] === "corr" ? ", your correction" : q[2] === "lost" ? ", lost (the tracker's guess)" :
             q[2] === "missing" ? ", no row in this frame (drawn where the nearest frame has it)" : "") +
            (sg && q[2] !== "corr" ? `, σ ${sg.toFixed(2)} px` : "") + ` — its path ±${TRAIL} frames is dotted; drag it to correct it`);
      }
    }
  });
  canvas.addEventListener("wheel", ev => {
    ev.preventDefault();
    const [cx, cy] = eventXY(ev);
    zoomAt(ev.deltaY < 0 ? 1.25 : 0.8, cx, cy);
  }, { passive: false });
  timeline.addEventListener("pointerdown", ev => {
    const r = timeline.getBoundingClientRect();
    showFrame((ev.clientX - r.left) / r.width * (info.n_frames - 1));
  });
  document.addEventListener("keydown", ev => {
    if (!info) return;
    const k = ev.key;
    if ((ev.ctrlKey || ev.metaKey) && k === "z") { ev.preventDefault(); undo(); }
    else if ((ev.ctrlKey || ev.metaKey) && k === "s") { ev.preventDefault(); save(); }
    else if (ev.ctrlKey || ev.metaKey || ev.altKey) return;
    else if (k === "ArrowRight" || k === "ArrowLeft") {
      ev.preventDefault();
      showFrame(frame + (k === "ArrowRight" ? 1 : -1) * (ev.shiftKey ? 10 : 1));
    }
    else if (k === "Home") showFrame(0);
    else if (k === "End") showFrame(info.n_frames - 1);
    else if (k === "n" || k === "N") jumpFlag(1);
    else if (k === "p" || k === "P") jumpFlag(-1);
    else if (k === " ") { ev.preventDefault(); togglePlay(); }
    else if (k === "r" || k === "R") retrack();
    else if ((k === "Delete" || k === "Backspace") && selected !== null) {
      const kk = key(frame, info.nodes[selected]);
      if (corrections.has(kk)) { pushUndo(); corrections.delete(kk); changed("correction dropped"); }
    }
    else if (k === "+" || k === "=") zoomAt(1.25, canvas.width / 2, canvas.height / 2);
    else if (k === "-") zoomAt(0.8, canvas.width / 2, canvas.height / 2);
    else if (k === "0") fit();
  });

  // ---------------------------------------------------------------- buttons
  $("undo").onclick = undo;
  $("zoom-fit").onclick = fit;
  $("step-back").onclick = () => showFrame(frame - 1);
  $("step-fwd").onclick = () => showFrame(frame + 1);
  $("prev-flag").onclick = () => jumpFlag(-1);
  $("next-flag").onclick = () => jumpFlag(1);
  $("play").onclick = togglePlay;
  $("retrack").onclick = retrack;
  $("save").onclick = save;
  $("finish").onclick = async () => {
    if (!(await save())) return;
    await post("/api/quit", {});
    say(statusEl.textContent + " — session finished; you can close this tab");
    for (const b of document.querySelectorAll("button, input")) b.disabled = true;
  };
  slider.oninput = () => showFrame(Number(slider.value));

  // ---------------------------------------------------------------- start
  window.addEventListener("resize", resize);
  (async () => {
    try {
      info = await (await fetch("/api/info")).json();
      const t = await (await fetch("/api/tracks")).json();
      $("title").textContent = "rce review";
      $("subtitle").textContent = `${info.video} · ${info.width}×${info.height} · ${info.n_frames} frames`;
      document.title = `rce review — ${info.video}`;
      slider.max = String(Math.max(0, info.n_frames - 1));
      const r = info.rules;
      $("flag-rules").textContent = `lost: not visible · large σ: > max(${r.sigma_min_px} px, ${r.sigma_factor}× the ` +
        `node's median) · jump: 2nd difference > max(${r.jump_min_px} px, ${r.jump_mads} robust SD)` +
        (info.has_sigma ? "" : " · these tracks have no σ column: fixed markers");
      corrections = new Map(info.corrections.map(c => [key(c.frame, c.node), c]));
      retrackedKey = corrKey();  // the tracks file was saved from these corrections (or there are none)
      resize();
      setTracks(t);
      renderCorrections();
      showFrame(0);
      say(`${info.nodes.length} nodes; ${t.flags.length} flagged run${t.flags.length === 1 ? "" : "s"} (N/P to step through ` +
          `them); drag a node to correct it, R to re-track, Ctrl+S to save`);
    } catch (e) { say(`cannot reach the rce review server: ${e.message}`, "error"); }
  })();

  // for tests and scripting: read-only views of the state and the coordinate transform
  window.rce = {
    get ready() { return info !== null && tracks !== null && frameShown >= 0; },
    get pending() { return pending; },
    get frameShown() { return frameShown; },
    get frame() { return frame; },
    state: () => ({ corrections: corrList(), frame, selected, stale: stale() }),
    position: (node, f) => position(nodeIndex(node), f),
    toClient: (x, y) => {
      const r = canvas.getBoundingClientRect();
      const [cx, cy] = toCanvas(x, y);
      return [r.left + cx, r.top + cy];
    },
  };
})();
