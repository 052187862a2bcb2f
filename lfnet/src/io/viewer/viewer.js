// The lfnet light-field viewer: parallax under the mouse, shift-and-add refocus, EPIs through
// a clicked point, and (with the truth) the error map and per-view PSNR. Plain JavaScript, no
// network: io::write_viewer embeds this file and the views (PNG data URIs) in index.html.
// Axes follow docs/conventions.md: u is the angular row (vertical parallax), v the column. A
// sequence's T frames come frame by frame (views[(t * U + u) * V + v]) with a time slider.
'use strict';
(function () {
  const kErrorMax = 0.1;  // |error| at the top of the error map's colour bar
  const kEpiScale = 8;    // EPI rows per view
  const started = performance.now();
  const errors = [];
  window.addEventListener('error', (e) => errors.push(String(e.message)));
  window.addEventListener('unhandledrejection', (e) => errors.push(String(e.reason)));

  const data = JSON.parse(document.getElementById('lfnet-data').textContent);
  const U = data.rows, V = data.cols, H = data.height, W = data.width, T = data.frames || 1;
  const uc = (U - 1) / 2, vc = (V - 1) / 2;
  const state = {
    u: Math.floor(U / 2), v: Math.floor(V / 2), x: Math.floor(W / 2), y: Math.floor(H / 2),
    disparity: 0, show: 'estimate', t: 0,
  };
  const $ = (id) => document.getElementById(id);
  const images = {estimate: null, truth: null};  // [at(u, v)] -> HTMLImageElement
  const pixels = {estimate: [], truth: []};      // lazily read grey values per view
  // The index of view (u, v) of the current frame.
  const at = (u, v) => (state.t * U + u) * V + v;
  const frameText = () => (T > 1 ? `frame ${state.t + 1} of ${T}, ` : '');

  function canvas(id, width, height) {
    const c = $(id);
    c.width = width;
    c.height = height;
    return c.getContext('2d');
  }

  async function decode(uris) {
    return Promise.all(uris.map(async (uri) => {
      const img = new Image();
      img.src = uri;
      await img.decode();
      return img;
    }));
  }

  // Grey values in [0, 1] of one view, read once.
  function grey(which, index) {
    if (!pixels[which][index]) {
      const g = document.createElement('canvas').getContext('2d', {willReadFrequently: true});
      g.canvas.width = W;
      g.canvas.height = H;
      g.drawImage(images[which][index], 0, 0);
      const rgba = g.getImageData(0, 0, W, H).data;
      const out = new Float32Array(W * H);
      for (let i = 0; i < out.length; ++i) {
        out[i] = (rgba[4 * i] + rgba[4 * i + 1] + rgba[4 * i + 2]) / (3 * 255);
      }
      pixels[which][index] = out;
    }
    return pixels[which][index];
  }

  // The viridis table lfnet colours every picture with (core/colour_map.h), 256 RGB entries.
  const kViridis = data.viridis;
  function viridis(t) {
    return kViridis[Math.round(Math.min(Math.max(t, 0), 1) * (kViridis.length - 1))];
  }

  function drawView() {
    const g = $('view').getContext('2d');
    g.drawImage(images[state.show][at(state.u, state.v)], 0, 0);
    g.strokeStyle = 'rgba(255, 80, 80, 0.9)';
    g.lineWidth = Math.max(1, W / 400);
    g.beginPath();
    g.moveTo(0, state.y + 0.5);
    g.lineTo(W, state.y + 0.5);
    g.moveTo(state.x + 0.5, 0);
    g.lineTo(state.x + 0.5, H);
    g.stroke();
    $('view-label').textContent = `${state.show}, ${frameText()}view (u, v) = (${state.u + 1}, ${state.v + 1})` +
        ` of ${U} x ${V}; EPIs through (x, y) = (${state.x}, ${state.y})`;
  }

  // Shift-and-add: every view moved by disparity * (its offset from the centre) and averaged,
  // as a running mean (alpha 1 / (k + 1) for the k-th view), so the focal plane is sharp.
  function drawRefocus() {
    const g = $('refocus').getContext('2d');
    g.globalAlpha = 1;
    g.fillStyle = 'black';
    g.fillRect(0, 0, W, H);
    let k = 0;
    for (let u = 0; u < U; ++u) {
      for (let v = 0; v < V; ++v, ++k) {
        g.globalAlpha = 1 / (k + 1);
        g.drawImage(images[state.show][at(u, v)], -state.disparity * (v - vc),
            -state.disparity * (u - uc));
      }
    }
    g.globalAlpha = 1;
    $('refocus-label').textContent =
        `refocused at ${state.disparity.toFixed(1)} px per view step (shift-and-add)`;
  }

  function drawEpis() {
    const h = $('epi-h').getContext('2d');
    for (let v = 0; v < V; ++v) {
      h.drawImage(images[state.show][at(state.u, v)], 0, state.y, W, 1, 0, v * kEpiScale, W,
          kEpiScale);
    }
    const t = $('epi-v').getContext('2d');
    t.setTransform(0, 1, 1, 0, 0, 0);  // swap axes: the column reads left to right
    for (let u = 0; u < U; ++u) {
      t.drawImage(images[state.show][at(u, state.v)], state.x, 0, 1, H, u * kEpiScale, 0,
          kEpiScale, H);
    }
    t.setTransform(1, 0, 0, 1, 0, 0);
  }

  function drawError() {
    if (!images.truth) return;
    const index = at(state.u, state.v);
    const a = grey('estimate', index), b = grey('truth', index);
    const g = $('error').getContext('2d');
    const out = g.createImageData(W, H);
    let sq = 0;
    for (let i = 0; i < a.length; ++i) {
      const e = Math.abs(a[i] - b[i]);
      sq += e * e;
      const [r, gr, bl] = viridis(e / kErrorMax);
      out.data[4 * i] = r;
      out.data[4 * i + 1] = gr;
      out.data[4 * i + 2] = bl;
      out.data[4 * i + 3] = 255;
    }
    g.putImageData(out, 0, 0);
    const psnr = data.per_view_psnr_db ? data.per_view_psnr_db[state.t * U + state.u][state.v] :
        10 * Math.log10(a.length / Math.max(sq, 1e-12));
    $('error-label').textContent = `|estimate - truth|, ${frameText()}view (${state.u + 1}, ${state.v + 1}): ` +
        `PSNR ${psnr === null ? 'inf' : psnr.toFixed(2)} dB`;
  }

  function colourBar() {
    const g = canvas('error-bar', 256, 14);
    for (let i = 0; i < 256; ++i) {
      const [r, gr, b] = viridis(i / 255);
      g.fillStyle = `rgb(${r},${gr},${b})`;
      g.fillRect(i, 0, 1, 14);
    }
  }

  // The U x V table of the current frame's per-view PSNR, coloured on one range for every
  // frame, the current view outlined.
  function psnrTable() {
    const table = $('psnr');
    const all = data.per_view_psnr_db;
    if (!all) return;
    table.replaceChildren();
    const values = all.slice(state.t * U, (state.t + 1) * U);
    const finite = all.flat().filter((x) => x !== null);
    const lo = Math.min(...finite), hi = Math.max(...finite);
    $('psnr-range').textContent = `${frameText()}colour: ${lo.toFixed(2)} dB (dark) to ` +
        `${hi.toFixed(2)} dB`;
    const head = table.insertRow();
    head.insertCell().textContent = 'u \\ v';
    for (let v = 0; v < V; ++v) head.insertCell().textContent = v + 1;
    for (let u = 0; u < U; ++u) {
      const row = table.insertRow();
      row.insertCell().textContent = u + 1;
      for (let v = 0; v < V; ++v) {
        const cell = row.insertCell();
        const x = values[u][v];
        cell.textContent = x === null ? 'inf' : x.toFixed(2);
        const [r, g, b] = viridis(x === null ? 1 : (x - lo) / Math.max(hi - lo, 1e-9));
        cell.style.background = `rgb(${r},${g},${b})`;
        cell.style.color = (r + g + b) / 3 > 128 ? 'black' : 'white';
        cell.dataset.u = u;
        cell.dataset.v = v;
        cell.addEventListener('click', () => setView(u, v));
      }
    }
  }

  function markTable() {
    for (const cell of document.querySelectorAll('#psnr td[data-u]')) {
      const on = +cell.dataset.u === state.u && +cell.dataset.v === state.v;
      cell.classList.toggle('current', on);
    }
  }

  function redraw() {
    drawView();
    drawEpis();
    drawError();
    markTable();
  }

  function setView(u, v) {
    u = Math.min(Math.max(u, 0), U - 1);
    v = Math.min(Math.max(v, 0), V - 1);
    if (u === state.u && v === state.v) return;
    state.u = u;
    state.v = v;
    redraw();
  }

  function setTime(t) {
    t = Math.min(Math.max(Math.round(t), 0), T - 1);
    $('time').value = t;
    $('time-label').textContent = `${t + 1} of ${T}`;
    if (t === state.t) return;
    state.t = t;
    psnrTable();
    redraw();
    drawRefocus();
  }

  function setDisparity(d) {
    state.disparity = d;
    $('disparity').value = d;
    drawRefocus();
  }

  function pick(x, y) {
    state.x = Math.min(Math.max(Math.round(x), 0), W - 1);
    state.y = Math.min(Math.max(Math.round(y), 0), H - 1);
    redraw();
  }

  function setShow(which) {
    if (!images[which]) return;
    state.show = which;
    $('show').value = which;
    redraw();
    drawRefocus();
  }

  // Position of a mouse event in the pixels of a canvas shown at any size.
  function position(e, c) {
    const r = c.getBoundingClientRect();
    return [(e.clientX - r.left) / r.width, (e.clientY - r.top) / r.height];
  }

  function bind() {
    const view = $('view');
    view.addEventListener('mousemove', (e) => {
      const [fx, fy] = position(e, view);
      setView(Math.round(fy * (U - 1)), Math.round(fx * (V - 1)));
    });
    view.addEventListener('click', (e) => {
      const [fx, fy] = position(e, view);
      pick(fx * W, fy * H);
    });
    $('refocus').addEventListener('click', (e) => {
      const [fx, fy] = position(e, $('refocus'));
      pick(fx * W, fy * H);
    });
    $('disparity').addEventListener('input', (e) => setDisparity(+e.target.value));
    $('show').addEventListener('change', (e) => setShow(e.target.value));
    $('time').addEventListener('input', (e) => setTime(+e.target.value));
    document.addEventListener('keydown', (e) => {
      const moves = {ArrowLeft: [0, -1], ArrowRight: [0, 1], ArrowUp: [-1, 0], ArrowDown: [1, 0]};
      if (moves[e.key]) {
        setView(state.u + moves[e.key][0], state.v + moves[e.key][1]);
        e.preventDefault();
      } else if (e.key === '+' || e.key === '-') {
        const step = e.key === '+' ? 0.1 : -0.1;
        setDisparity(Math.round((state.disparity + step) * 10) / 10);
      } else if (e.key === '[' || e.key === ']') {
        setTime(state.t + (e.key === ']' ? 1 : -1));
      }
    });
  }

  function describe() {
    document.title = `lfnet viewer: ${data.title}`;
    $('title').textContent = data.scale > 1
      ? `${data.title} (views of ${data.full_width}x${data.full_height} shown at 1/${data.scale})`
      : data.title;
    const r = data.record || {};
    const facts = [];
    if (r.method) facts.push(`method ${r.method}`);
    if (r.phi && r.phi.name) facts.push(`Phi ${r.phi.name}` + (r.measurements ? `, N ${r.measurements}` : ''));
    if (r.whole_image) facts.push('whole image');
    else if (r.stride) facts.push(`stride ${r.stride}`);
    if (r.mode) facts.push(`${r.mode} mode`);
    // A colour net reconstructs the colours with the views; pinv's views are demosaiced (the
    // record says how).
    const colourWay = r.whole_image ? 'colours reconstructed jointly'
      : 'demosaiced' + (r.demosaic ? ` (${r.demosaic})` : '');
    if (r.cfa) facts.push(r.cfa.pattern ? `Bayer ${r.cfa.pattern}, ${colourWay}` : `colour filter array, ${colourWay}`);
    if (r.camera_error) facts.push('camera off its Phi');
    if (typeof r.psnr_db === 'number') facts.push(`PSNR ${r.psnr_db.toFixed(2)} dB` + (r.cfa ? ' (colour)' : ''));
    if (typeof r.luma_psnr_db === 'number') facts.push(`luma ${r.luma_psnr_db.toFixed(2)} dB`);
    if (typeof r.ssim === 'number') facts.push(`SSIM ${r.ssim.toFixed(4)}`);
    if (typeof r.seconds === 'number') facts.push(`${r.seconds.toFixed(2)} s`);
    facts.push((T > 1 ? `${T} frames of ` : '') + `${U} x ${V} views of ${W} x ${H} pixels`);
    $('facts').textContent = facts.join(' · ');
  }

  async function start() {
    describe();
    for (const id of ['view', 'refocus', 'error']) canvas(id, W, H);
    canvas('epi-h', W, V * kEpiScale);
    canvas('epi-v', H, U * kEpiScale);
    const [estimate, truth] = await Promise.all(
        [decode(data.views), data.truth ? decode(data.truth) : Promise.resolve(null)]);
    images.estimate = estimate;
    images.truth = truth;
    if (!truth) {
      for (const id of ['error-panel', 'psnr-panel']) $(id).hidden = true;
      $('show').querySelector('option[value=truth]').disabled = true;
    } else {
      colourBar();
      psnrTable();
    }
    const span = Math.max(4, Math.ceil(data.max_disparity || 4));
    $('disparity').min = -span;
    $('disparity').max = span;
    $('time-control').hidden = T < 2;
    $('time').max = T - 1;
    setTime(0);
    bind();
    redraw();
    drawRefocus();
    api.loadMs = performance.now() - started;
    $('status').textContent = `loaded in ${Math.round(api.loadMs)} ms · mouse over the view: ` +
        'parallax; arrows: step views; click: EPIs through a point; + / -: refocus' +
        (T > 1 ? '; [ / ]: step frames' : '');
  }

  const api = {state, errors, loadMs: null, setView, setDisparity, pick, setShow, setTime};
  api.ready = start().catch((e) => {
    errors.push(String(e));
    $('status').textContent = `cannot show the light field: ${e}`;
  });
  window.lfnetViewer = api;
})();
