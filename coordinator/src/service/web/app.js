// Photonfarm's web page: plain JavaScript, no build step. Every piece of data comes from the
// JSON API with the token as an Authorization header; the token lives in sessionStorage (this
// tab only) and is never put in a URL. Text from the API is set as text, never as HTML.
'use strict';

const KEY = 'photonfarm-token';
const POLL_MS = 1500;
let token = sessionStorage.getItem(KEY);
let timer = null;
let generation = 0; // bumped on every navigation, so a late answer never paints an old view

const $ = (id) => document.getElementById(id);

/** An element with attributes and children (strings become text nodes). */
function h(tag, attrs, ...children) {
  const ns = ['svg', 'line', 'polyline', 'circle', 'text', 'path', 'g', 'rect', 'title'].includes(tag)
    ? 'http://www.w3.org/2000/svg' : null;
  const el = ns ? document.createElementNS(ns, tag) : document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === null || v === undefined || v === false) continue;
    if (k.startsWith('on')) el.addEventListener(k.slice(2), v);
    // Through the CSSOM: the page's CSP refuses style attributes.
    else if (k === 'style') el.style.cssText = v;
    else el.setAttribute(k, v === true ? '' : String(v));
  }
  for (const c of children.flat(Infinity)) {
    if (c !== null && c !== undefined) el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return el;
}

class Unauthorized extends Error {}

/** Calls the API; a 401 logs out. Returns the parsed JSON, or the Response for `raw`. */
async function api(path, opts = {}) {
  const headers = new Headers(opts.headers || {});
  if (token) headers.set('Authorization', 'Bearer ' + token);
  const r = await fetch(path, { ...opts, headers, cache: 'no-store', referrerPolicy: 'no-referrer' });
  if (r.status === 401) throw new Unauthorized();
  if (!r.ok) {
    let msg = r.status + ' ' + r.statusText;
    try { msg = (await r.json()).error || msg; } catch (_) { /* not JSON */ }
    throw new Error(msg);
  }
  return opts.raw ? r : r.json();
}

function fmtRate(r) { return r > 0 ? (r >= 10 ? r.toFixed(1) : r.toFixed(2)) + ' /s' : '—'; }
function fmtDuration(s) {
  if (!isFinite(s) || s < 0) return '—';
  s = Math.round(s);
  if (s < 60) return s + ' s';
  if (s < 3600) return Math.floor(s / 60) + ' min ' + (s % 60) + ' s';
  return Math.floor(s / 3600) + ' h ' + Math.floor((s % 3600) / 60) + ' min';
}
function timeLeft(j) {
  if (j.state === 'done') return '—';
  if (j.state !== 'running' || j.rate <= 0) return '—';
  return fmtDuration((j.iterations_total - j.iterations_done) / j.rate);
}
function fmtBytes(b) {
  const u = ['B', 'KB', 'MB', 'GB', 'TB'];
  let i = 0;
  while (b >= 1000 && i < u.length - 1) { b /= 1000; i++; }
  return (i ? b.toFixed(1) : b) + ' ' + u[i];
}
function stateTag(s) { return h('span', { class: 'state ' + s, 'data-state': s }, s); }
function progress(j) {
  const pct = j.iterations_total ? (100 * j.iterations_done / j.iterations_total) : 0;
  return [h('span', { class: 'bar' }, h('span', { style: 'width:' + pct.toFixed(1) + '%' })),
    j.iterations_done + ' / ' + j.iterations_total];
}

// ---- views -------------------------------------------------------------------------------

const views = {
  /** Every job. */
  async jobs(root) {
    const { jobs } = await api('/api/jobs');
    const rows = jobs.slice().reverse().map((j) => h('tr', { 'data-job': j.id },
      h('td', null, h('a', { href: '#/jobs/' + j.id }, 'Job ' + j.id)),
      h('td', null, stateTag(j.state)),
      h('td', null, progress(j)),
      h('td', { class: 'num' }, fmtRate(j.rate)),
      h('td', { class: 'num' }, timeLeft(j)),
      h('td', null, j.workers.length ? j.workers.join(', ') : h('span', { class: 'muted' }, 'none')),
      h('td', { class: 'muted' }, j.integrator + ', ' + j.width + '×' + j.height),
      h('td', { class: 'muted' }, new Date(j.created_unix_ms).toLocaleString())));
    root.replaceChildren(
      h('h2', null, 'Jobs'),
      jobs.length ? h('table', { id: 'jobs' },
        h('thead', null, h('tr', null, h('th', null, 'Job'), h('th', null, 'State'),
          h('th', null, 'Passes'), h('th', { class: 'num' }, 'Rate'), h('th', { class: 'num' }, 'Time left'),
          h('th', null, 'Workers'), h('th', null, 'Method'), h('th', null, 'Submitted'))),
        h('tbody', null, rows))
        : h('p', { class: 'muted', id: 'no-jobs' }, 'No jobs yet. ', h('a', { href: '#/submit' }, 'Submit one.')));
  },

  /** One job: status, latest image, noise chart, cancel. */
  async job(root, id, state) {
    const [j, noise] = await Promise.all([api('/api/jobs/' + id), api('/api/jobs/' + id + '/noise')]);
    if (!state.built) {
      state.built = true;
      state.img = h('img', { id: 'job-image', alt: 'latest checkpoint of job ' + id });
      // Raw or denoised, for a job submitted with --denoise; the choice holds across refreshes.
      state.view = 'image';
      const choice = (name, label) => h('label', null,
        h('input', { type: 'radio', name: 'view', value: name, checked: name === 'image' ? '' : null,
          onchange: () => { state.view = name; state.imagePasses = -1; refresh(); } }), ' ' + label);
      state.toggle = h('div', { id: 'view-toggle', hidden: '' },
        choice('image', 'Raw'), choice('image.denoised', 'Denoised'));
      state.imageBox = h('div', { id: 'image-box' }, h('span', { class: 'empty' }, 'no checkpoint yet'));
      state.details = h('dl', { id: 'job-details' });
      state.title = h('h2', { id: 'job-title' });
      state.cancel = h('button', { type: 'button', id: 'cancel', class: 'danger', onclick: async () => {
        state.cancel.disabled = true;
        try { await api('/api/jobs/' + id, { method: 'DELETE' }); } catch (e) { state.error.textContent = e.message; }
        refresh();
      } }, 'Cancel job');
      state.error = h('p', { class: 'error', id: 'job-error' });
      state.chart = h('div', { id: 'noise-chart' });
      state.strip = h('div', { id: 'frames' });
      state.thumbs = new Map();
      root.replaceChildren(state.title,
        h('div', { class: 'cards' },
          h('div', { class: 'card' }, h('h3', null, 'Latest checkpoint'), state.toggle, state.imageBox),
          h('div', { class: 'stack' },
            h('div', { class: 'card' }, h('h3', null, 'Status'), state.details, state.cancel, state.error),
            h('div', { class: 'card' }, h('h3', null, 'Convergence, without a reference'), state.chart,
              h('p', { class: 'hint' }, 'Estimated variance of the image (its expected squared error against the ',
                'converged image) from the difference of its even and odd passes. Dashed: falling as 1/passes.')))));
    }
    state.title.replaceChildren('Job ' + j.id + ' ', stateTag(j.state));
    const rows = [
      ['Passes', progress(j)], ['Checkpoint', j.checkpoint_iterations + ' passes'],
      ['Rate', fmtRate(j.rate)], ['Time left', timeLeft(j)], ['Elapsed', fmtDuration(j.elapsed_seconds)],
      ['Workers', j.workers.length ? j.workers.join(', ') : 'none'],
      ['Method', j.integrator + ', ' + j.width + '×' + j.height],
      ['Received', j.batches_received + ' batches, ' + fmtBytes(j.bytes_received)],
    ];
    if (j.message) rows.push(['Message', j.message]);
    state.details.replaceChildren(...rows.flatMap(([k, v]) => [h('dt', null, k), h('dd', null, v)]));
    state.cancel.hidden = ['done', 'failed', 'cancelled'].includes(j.state);
    state.toggle.hidden = !j.denoise;
    if (j.checkpoint_iterations > 0 && j.checkpoint_iterations !== state.imagePasses) {
      // The preview follows its checkpoint by the denoiser's time: shown at a later refresh.
      const blob = await api('/api/jobs/' + id + '/' + state.view + '.png', { raw: true })
        .then((r) => r.blob(), () => null);
      if (blob) showImage(state, blob, j);
      else state.imageBox.replaceChildren(h('span', { class: 'empty', id: 'no-preview' }, 'no denoised preview yet'));
    }
    state.chart.replaceChildren(chart(noise));
    if (j.frames && j.frames.length) await frameStrip(root, state, j);
  },

  /** The workers seen lately. */
  async workers(root) {
    const { workers } = await api('/api/workers');
    if (!workers.length) {
      root.replaceChildren(h('h2', null, 'Workers'), h('p', { class: 'muted' }, 'No worker has asked for work lately.'));
      return;
    }
    const lease = (w) => w.leases.length
      ? w.leases.map((l, i) => [i ? ', ' : '', h('a', { href: '#/jobs/' + l.job }, 'job ' + l.job),
        ' passes ' + l.start + '–' + (l.end - 1)])
      : h('span', { class: 'muted' }, 'idle');
    const row = (w) => h('tr', null,
      h('td', null, w.name), h('td', { class: 'num' }, w.threads), h('td', null, lease(w)),
      h('td', { class: 'num' }, w.rate > 0 ? w.rate.toFixed(2) : '—'), h('td', { class: 'num' }, w.passes),
      h('td', { class: 'num' }, fmtDuration(w.last_seen_seconds) + ' ago'));
    const head = h('tr', null, h('th', null, 'Name'), h('th', { class: 'num' }, 'Threads'),
      h('th', null, 'Current lease'), h('th', { class: 'num' }, 'Passes/s'), h('th', { class: 'num' }, 'Passes done'),
      h('th', { class: 'num' }, 'Last seen'));
    root.replaceChildren(h('h2', null, 'Workers'),
      h('table', { id: 'workers' }, h('thead', null, head), h('tbody', null, workers.map(row))));
  },

  /** Submitting a bundle, as `coordinator submit` does. */
  async submit(root, _id, state) {
    if (state.built) return;
    state.built = true;
    const field = (label, input) => [h('label', { for: input.id }, label), input];
    const num = (id, placeholder) => h('input', { id, type: 'number', min: 0, placeholder });
    const form = h('form', { class: 'grid', id: 'submit-form' },
      field('Bundle (tar)', h('input', { id: 'bundle', type: 'file', accept: '.tar,application/x-tar', required: true })),
      field('Scene in bundle', h('input', { id: 'scene', placeholder: 'the only top-level .xml' })),
      field('Integrator', h('select', { id: 'integrator' }, h('option', { value: '' }, "the scene's"),
        h('option', { value: 'path' }, 'path'), h('option', { value: 'sppm' }, 'sppm'), h('option', { value: 'direct' }, 'direct'),
        h('option', { value: 'ptracer' }, 'ptracer'), h('option', { value: 'hybrid' }, 'hybrid'))),
      field('Passes', num('passes', "the scene's sample_count")),
      field('Photons (SPPM)', num('photons', 'pixels / 4, at least 16384')),
      field('Seed', num('seed', '0')),
      field('Checkpoint every', num('checkpoint_every', 'the coordinator default')),
      field('Defines', h('input', { id: 'defines', placeholder: 'res=256 spp=64' })),
      h('span'), h('button', { type: 'submit', id: 'submit-button' }, 'Submit'));
    const out = h('p', { id: 'submit-result' });
    form.addEventListener('submit', async (ev) => {
      ev.preventDefault();
      const settings = {};
      const v = (id) => $(id).value.trim();
      if (v('integrator')) settings.integrator = v('integrator');
      for (const k of ['passes', 'photons', 'seed', 'checkpoint_every']) if (v(k)) settings[k] = Number(v(k));
      if (v('defines')) settings.defines = v('defines').split(/\s+/).map((d) => d.split('=', 2)).map(([a, b]) => [a, b ?? '']);
      const data = new FormData();
      data.append('bundle', $('bundle').files[0]);
      if (v('scene')) data.append('scene', v('scene'));
      data.append('settings', JSON.stringify(settings));
      out.className = ''; out.textContent = 'Uploading…';
      try {
        const job = await api('/api/jobs', { method: 'POST', body: data });
        location.hash = '#/jobs/' + job.id;
      } catch (e) {
        if (e instanceof Unauthorized) return logout();
        out.className = 'error'; out.textContent = e.message;
      }
    });
    root.replaceChildren(h('h2', null, 'Submit a job'),
      h('p', { class: 'hint' }, 'A tar archive of the scene and every file it reads (as coordinator submit packs it).'),
      h('div', { class: 'card' }, form, out));
  },
};

/** Shows a job's image (raw or denoised, as `state.view` says) from a PNG blob. */
function showImage(state, blob, j) {
  const old = state.img.getAttribute('src');
  state.img.src = URL.createObjectURL(blob);
  state.img.dataset.passes = j.checkpoint_iterations;
  state.img.dataset.view = state.view;
  if (old) URL.revokeObjectURL(old);
  state.imagePasses = j.checkpoint_iterations;
  state.imageBox.replaceChildren(state.img);
}

/** A sequence's frames as a strip of thumbnails, each with its state, linking to the frame's
 *  job; a thumbnail is fetched again only when its frame has a newer checkpoint. */
async function frameStrip(root, state, j) {
  if (!state.strip.isConnected) {
    root.append(h('div', { class: 'card', id: 'frames-card' }, h('h3', null, 'Frames'), state.strip));
  }
  const figures = [];
  for (const f of j.frames) {
    let t = state.thumbs.get(f.frame);
    if (!t) {
      t = { img: h('img', { alt: 'frame ' + f.frame }), passes: 0, caption: h('figcaption') };
      t.figure = h('a', { href: '#/jobs/' + f.job, class: 'frame', 'data-frame': f.frame },
        h('figure', null, t.img, t.caption));
      state.thumbs.set(f.frame, t);
    }
    t.figure.dataset.state = f.state;
    t.caption.replaceChildren('frame ' + f.frame + ' ', stateTag(f.state));
    if (f.checkpoint_iterations > 0 && f.checkpoint_iterations !== t.passes) {
      const blob = await (await api('/api/jobs/' + f.job + '/image.png', { raw: true })).blob();
      const old = t.img.getAttribute('src');
      t.img.src = URL.createObjectURL(blob);
      if (old) URL.revokeObjectURL(old);
      t.passes = f.checkpoint_iterations;
    }
    figures.push(t.figure);
  }
  state.strip.replaceChildren(...figures);
}

/** A log-log SVG chart of the noise estimates, with a 1/passes line through the first point. */
function chart(noise) {
  const pts = noise.points.filter((p) => p.passes > 0 && p.variance > 0);
  if (pts.length === 0) {
    return h('p', { class: 'muted', id: 'no-noise' },
      noise.tracking ? 'No estimate yet: it needs an even and an odd pass.' : 'No estimate: a worker sent results without their odd passes.');
  }
  const W = 540, H = 250, L = 58, R = 12, T = 10, B = 36;
  const lx = (v) => Math.log10(v);
  let [x0, x1] = [lx(pts[0].passes), lx(pts[pts.length - 1].passes)];
  let ys = pts.map((p) => lx(p.variance));
  let [y0, y1] = [Math.min(...ys), Math.max(...ys)];
  if (x1 - x0 < 1) { x0 = Math.floor(x0); x1 = Math.max(x1, x0 + 1); }
  if (y1 - y0 < 1) { const m = (y0 + y1) / 2; y0 = m - 0.5; y1 = m + 0.5; }
  x0 = Math.floor(x0 * 10) / 10; x1 = Math.ceil(x1 * 10) / 10; y0 = Math.floor(y0 * 10) / 10; y1 = Math.ceil(y1 * 10) / 10;
  const X = (v) => L + (lx(v) - x0) / (x1 - x0) * (W - L - R);
  const Y = (v) => T + (y1 - lx(v)) / (y1 - y0) * (H - T - B);
  const svg = h('svg', { viewBox: `0 0 ${W} ${H}`, width: '100%', role: 'img', 'aria-label': 'noise estimate against passes' });
  const ticks = (a, b) => {
    const out = [];
    for (let e = Math.floor(a); e <= Math.ceil(b); e++) {
      for (const m of (b - a > 2.5 ? [1] : [1, 2, 5])) {
        const v = m * 10 ** e;
        if (lx(v) >= a - 1e-9 && lx(v) <= b + 1e-9) out.push(v);
      }
    }
    return out;
  };
  const label = (v) => (v >= 1e-2 && v < 1e5) ? String(+v.toPrecision(3)) : v.toExponential(0).replace('e+', 'e');
  for (const v of ticks(x0, x1)) {
    svg.append(h('line', { x1: X(v), x2: X(v), y1: T, y2: H - B, stroke: '#e6e9ef' }),
      h('text', { x: X(v), y: H - B + 16, 'text-anchor': 'middle' }, label(v)));
  }
  for (const v of ticks(y0, y1)) {
    svg.append(h('line', { x1: L, x2: W - R, y1: Y(v), y2: Y(v), stroke: '#e6e9ef' }),
      h('text', { x: L - 6, y: Y(v) + 4, 'text-anchor': 'end' }, label(v)));
  }
  svg.append(h('rect', { x: L, y: T, width: W - L - R, height: H - T - B, fill: 'none', stroke: '#c5ccd8' }),
    h('text', { x: (L + W - R) / 2, y: H - 6, 'text-anchor': 'middle' }, 'passes'),
    h('text', { x: 14, y: (T + H - B) / 2, 'text-anchor': 'middle', transform: `rotate(-90 14 ${(T + H - B) / 2})` }, 'estimated variance'));
  // 1/passes through the first point: where an unbiased estimate's noise goes.
  const p0 = pts[0], pEnd = 10 ** x1;
  const clip = (v) => Math.max(v, 10 ** y0);
  svg.append(h('line', { x1: X(p0.passes), y1: Y(p0.variance), x2: X(pEnd),
    y2: Y(clip(p0.variance * p0.passes / pEnd)), stroke: '#98a2b3', 'stroke-dasharray': '4 4' }));
  svg.append(h('polyline', { points: pts.map((p) => X(p.passes) + ',' + Y(p.variance)).join(' '),
    fill: 'none', stroke: '#2f6fde', 'stroke-width': 2 }));
  for (const p of pts) {
    svg.append(h('circle', { class: 'point', cx: X(p.passes), cy: Y(p.variance), r: 3, fill: '#2f6fde' },
      h('title', null, p.passes + ' passes: ' + p.variance.toExponential(3))));
  }
  return svg;
}

// ---- routing, polling, login --------------------------------------------------------------

function route() {
  const m = location.hash.match(/^#\/jobs\/(\d+)$/);
  if (m) return ['job', m[1]];
  if (location.hash === '#/workers') return ['workers'];
  if (location.hash === '#/submit') return ['submit'];
  return ['jobs'];
}

let current = { gen: -1, state: {} };

async function refresh() {
  clearTimeout(timer);
  const gen = generation;
  const [name, id] = route();
  if (current.gen !== gen) current = { gen, state: {} };
  for (const a of document.querySelectorAll('nav a')) a.classList.toggle('active', a.id === 'nav-' + (name === 'job' ? 'jobs' : name));
  try {
    await views[name]($('view'), id, current.state);
    $('footer').textContent = 'Updated ' + new Date().toLocaleTimeString();
  } catch (e) {
    if (e instanceof Unauthorized) return logout('The token was refused.');
    if (gen === generation) $('footer').textContent = 'Error: ' + e.message;
  }
  if (gen === generation && name !== 'submit') timer = setTimeout(refresh, POLL_MS);
}

function showApp() {
  $('login').hidden = true;
  $('nav').hidden = false;
  generation++;
  refresh();
}

/** Forgets the token and every piece of data on the page. */
function logout(message) {
  clearTimeout(timer);
  generation++;
  token = null;
  sessionStorage.removeItem(KEY);
  $('view').replaceChildren();
  $('footer').textContent = '';
  $('nav').hidden = true;
  $('login').hidden = false;
  $('login-error').textContent = typeof message === 'string' ? message : '';
  $('token').focus();
}

async function start() {
  window.addEventListener('hashchange', () => { generation++; if (!$('nav').hidden) refresh(); });
  $('logout').addEventListener('click', () => logout());
  $('login-form').addEventListener('submit', async (ev) => {
    ev.preventDefault();
    token = $('token').value.trim();
    $('token').value = '';
    try {
      await api('/api/jobs');
      sessionStorage.setItem(KEY, token);
      showApp();
    } catch (e) {
      logout(e instanceof Unauthorized ? 'The token was refused.' : 'Error: ' + e.message);
    }
  });
  // A coordinator without a users' token needs no login.
  try {
    await api('/api/jobs');
    showApp();
  } catch (e) {
    logout(token && e instanceof Unauthorized ? 'The token was refused.' : '');
  }
}

start();
