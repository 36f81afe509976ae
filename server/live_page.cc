#include "server/live_page.h"

namespace tessera {

const char* const kLivePage = R"HTML(<!doctype html>
<html><head><meta charset="utf-8"><title>Tessera</title><link rel="stylesheet" href="/app.css"></head><body>
<h2>Tessera</h2>
<div class="bar"><span id="summary"></span>
<label>token <input id="token" type="password" autocomplete="off" placeholder="for actions, and reads behind tokens"></label></div>
<div id="error" role="alert"></div>
<h3>Job <span id="shown"></span></h3>
<div class="row"><div><img id="preview" alt="no image yet"></div>
<div><canvas id="heat"></canvas><div id="frames"></div></div>
<div><pre id="settings"></pre><table id="job-events"></table></div></div>
<h3>Jobs <small>(click a row to show it)</small></h3><table id="jobs"></table>
<h3>Workers</h3><table id="workers"></table>
<h3>Events</h3><table id="events"></table>
<script src="/app.js"></script></body></html>)HTML";

const char* const kLiveCss = R"CSS(body{font-family:sans-serif;margin:1.5em;background:#111;color:#ddd}
table{border-collapse:collapse}td,th{padding:2px 10px;text-align:left}
tr.job{cursor:pointer}tr.job:hover,tr.shown{background:#223}
.row{display:flex;gap:1.5em;align-items:flex-start;flex-wrap:wrap}canvas,img{image-rendering:pixelated;border:1px solid #444}
#preview{max-width:40vw;max-height:50vh;height:auto}#heat{max-width:25vw;max-height:50vh}
#settings{max-height:30vh;overflow:auto;font-size:80%;margin:0}
.bar{display:flex;gap:2em;align-items:center}#error{color:#f66;min-height:1.2em}
button{background:#333;color:#ddd;border:1px solid #555;margin:0 2px;cursor:pointer}
.frame{display:inline-block;min-width:2.5em;margin:1px;padding:1px 3px;text-align:center;background:#333;color:#ddd}
.frame.DONE{background:#2a6}.frame.RUNNING{background:#c80}.frame.CANCELLED,.frame.FAILED{background:#733}
)CSS";

const char* const kLiveJs = R"JS('use strict';
const esc = v => String(v).replace(/[&<>"']/g, c => ({'&':'&amp;','<':'&lt;','>':'&gt;','"':'&quot;',"'":'&#39;'}[c]));
const $ = id => document.getElementById(id);
const tokenBox = $('token');
tokenBox.value = sessionStorage.getItem('tessera-token') || '';
tokenBox.addEventListener('change', () => { sessionStorage.setItem('tessera-token', tokenBox.value); tick(); });
const auth = () => tokenBox.value ? {'Authorization': 'Bearer ' + tokenBox.value} : {};
const say = msg => { $('error').textContent = msg || ''; };
async function get(url) {
  const r = await fetch(url, {headers: auth()});
  if (!r.ok) throw new Error(`${url}: ${r.status} ${(await r.text()).trim()}`);
  return r.json();
}
// An action: POST with the header a cross-site form cannot send, and the token.
async function act(url) {
  const r = await fetch(url, {method: 'POST', headers: Object.assign({'X-Tessera-Action': '1'}, auth())});
  const body = await r.json().catch(() => ({}));
  say(r.ok ? '' : `${url}: ${body.error || r.status}`);
  tick();
}
let chosen = null;                 // the job shown, as clicked (else the running one)
let heat = {id: null, from: 0};    // the tile map's job and next page
const when = t => t ? new Date(t).toLocaleString() : '-';
const eventRows = ev => '<tr><th>time</th><th>event</th><th>job</th><th>worker</th><th>who</th><th>detail</th></tr>' +
  ev.map(e=>`<tr><td>${esc(when(e.time))}</td><td>${esc(e.kind)}</td><td>${esc(e.job_id || '-')}</td><td>${esc(e.worker || '-')}</td><td>${esc(e.who || '-')}</td><td>${esc(e.detail)}</td></tr>`).join('');
document.addEventListener('click', ev => {
  const b = ev.target.closest('button[data-act]');
  if (b) {
    ev.stopPropagation();
    const [kind, id, what] = [b.dataset.kind, b.dataset.id, b.dataset.act];
    if (what === 'delete' && !confirm(`Delete job ${id} and its images?`)) return;
    let q = '';
    if (what === 'priority') {
      const p = prompt(`New priority for job ${id} (higher runs first)`, b.dataset.priority);
      if (p === null) return;
      q = '?value=' + encodeURIComponent(p.trim());
    }
    act(`/api/${kind}/${encodeURIComponent(id)}/${what}${q}`);
    return;
  }
  const row = ev.target.closest('tr.job');
  if (row) { chosen = row.dataset.id; heat = {id: null, from: 0}; tick(); }
});
const button = (kind, id, what, extra = '') =>
  `<button data-kind="${esc(kind)}" data-id="${esc(id)}" data-act="${esc(what)}" ${extra}>${esc(what)}</button>`;
async function tick() {
  let s;
  try { s = await get('/api/status'); } catch (e) { say(e.message); return; }
  const jobs = s.jobs || [], workers = s.workers || [];
  $('summary').textContent = `${jobs.length} jobs, ${workers.filter(w=>w.active).length} of ${workers.length} workers busy, ` +
    `${(100*s.utilization).toFixed(0)}% of their threads, up ${s.uptime_seconds.toFixed(0)} s`;
  const live = j => j.state === 'QUEUED' || j.state === 'RUNNING';
  $('jobs').innerHTML = '<tr><th>id</th><th>name</th><th>owner</th><th>priority</th><th>state</th><th>samples</th><th>passes / frames</th><th>submitted</th><th>ended</th><th>elapsed</th><th>ETA</th><th></th></tr>' +
    jobs.map(j=>`<tr class="${esc(j.id === chosen ? 'job shown' : 'job')}" data-id="${esc(j.id)}"><td>${esc(j.id)}</td><td>${esc(j.name)}</td><td>${esc(j.owner || '-')}</td><td>${esc(j.priority || 0)}</td><td>${esc(j.state)}</td><td>${esc((100*j.samples_done/Math.max(1,j.samples_total)).toFixed(1))}%</td><td>${esc(j.frames_total ? 'frames ' + j.frames_done + '/' + j.frames_total : j.frame_passes_done + '/' + j.passes_total)}</td><td>${esc(when(j.submitted_at))}</td><td>${esc(when(j.ended_at))}</td><td>${esc(j.elapsed_seconds.toFixed(0))} s</td><td>${esc(live(j) ? j.eta_seconds.toFixed(0) + ' s' : '-')}</td><td>` +
      (live(j) ? button('jobs', j.id, 'cancel') : button('jobs', j.id, 'requeue')) + button('jobs', j.id, 'priority', `data-priority="${esc(j.priority || 0)}"`) + button('jobs', j.id, 'delete') + '</td></tr>').join('');
  $('workers').innerHTML = '<tr><th>id</th><th>name</th><th>host</th><th>threads</th><th>samples/s</th><th>busy</th><th>tasks</th><th>leases</th><th>last task</th><th>last contact</th><th>round trip</th><th>bytes/sample</th><th></th></tr>' +
    workers.map(w=>`<tr><td>${esc(w.id)}</td><td>${esc(w.name)}</td><td>${esc(w.host || '-')}</td><td>${esc(w.threads)}</td><td>${esc((w.samples_per_second/1e6).toFixed(2))} M</td><td>${esc((100*w.utilization).toFixed(0))}%</td><td>${esc(w.tasks_done)}</td><td>${esc(w.leases)}</td><td>${esc(w.last_task || '-')}</td><td>${esc(w.seen_seconds_ago.toFixed(1))} s ago</td><td>${esc(w.round_trip_ms.toFixed(1))} ms</td><td>${esc(w.bytes_per_sample.toFixed(3))}</td><td>` +
      (w.draining ? 'draining ' + button('workers', w.id, 'resume') : button('workers', w.id, 'drain')) + '</td></tr>').join('');
  try { $('events').innerHTML = eventRows(((await get('/api/events?limit=20')).events || []).reverse()); } catch (e) { say(e.message); }
  const job = jobs.find(j=>j.id === chosen) || jobs.find(j=>j.state==='RUNNING') || jobs[jobs.length-1];
  if (!job) return;
  $('shown').textContent = `${job.id} ${job.name || ''}`;
  // The tile map a page of tiles per tick (the API's tiles_next), redrawn from the first.
  const tiles = id => `/api/jobs/${encodeURIComponent(id)}?tiles_from=${heat.id === id ? heat.from : 0}`;
  let id = job.id, d;
  try { d = await get(tiles(id)); } catch (e) { say(e.message); return; }
  $('settings').textContent = JSON.stringify(d.settings, null, 1);
  const jobEvents = '/api/events?limit=50&job=' + encodeURIComponent(job.id);
  try { $('job-events').innerHTML = eventRows((await get(jobEvents)).events || []); } catch (e) { say(e.message); }
  // A sequence: every frame by state, and the frame being rendered (else the last one
  // started) in the preview and the tile map.
  // (The first page of frames: the API's frames_next says more follow.)
  const frames = d.frames || [];
  $('frames').innerHTML = frames.length === 0 ? '' : frames.map(f =>
    `<span class="frame ${esc(f.state)}" title="${esc(f.state)}">${esc(f.frame)}</span>`).join('') +
    (d.frames_next == null ? '' : `<span class="frame">${esc('+' + (d.frames_total - frames.length) + ' more')}</span>`);
  if (d.frames_total) {
    if (!d.current_frame_job) return;
    id = d.current_frame_job;
    try { d = await get(tiles(id)); } catch (e) { say(e.message); return; }
  }
  // The preview through fetch (it carries the token), shown from a blob URL.
  fetch(`/jobs/${encodeURIComponent(id)}/preview.png?t=${Date.now()}`, {headers: auth()}).then(r => r.ok ? r.blob() : null).then(b => {
    if (!b) return;
    const old = $('preview').src;
    $('preview').src = URL.createObjectURL(b);
    if (old.startsWith('blob:')) URL.revokeObjectURL(old);
  });
  const c = $('heat'), ctx = c.getContext('2d');
  if (d.tiles_from === 0) {
    c.width = d.settings.width; c.height = d.settings.height;
    ctx.fillStyle = '#000'; ctx.fillRect(0, 0, c.width, c.height);
  }
  heat = {id, from: d.tiles_next ?? 0};
  for (const t of d.tiles || []) {
    const f = t.passes_done / Math.max(1, d.passes_total);
    ctx.fillStyle = t.finished ? '#fff' : `hsl(${240 - 240*f},80%,${25+35*f}%)`;
    ctx.fillRect((t.rect.x||0) + 1, (t.rect.y||0) + 1, t.rect.w - 2, t.rect.h - 2);  // 1-px gaps show tiles
  }
}
// A tick a second after the last one ended: slow answers never pile up.
(async function loop() { try { await tick(); } finally { setTimeout(loop, 1000); } })();
)JS";

}  // namespace tessera
