// The twindrive console page: one WebSocket to the master, reconnecting by
// itself; the map; the twin's controls; the plan's stages; the robots.
import { MapView, LodPath, Band, at } from './map.js';

const $ = (id) => document.getElementById(id);
const map = new MapView($('map'));

// One colour per thing on the map: the layers, the live overlay and the
// legend all take theirs from here.
const COLORS = {
  executed: '#a0aec0', deleted: '#e53e3e', uncovered: '#d53f8c', plan: '#2b6cb0',
  openLoop: '#38a169', closedLoop: '#319795', rehearsal: '#718096',
  twin: '#2b6cb0', bumped: '#e53e3e', robot: '#dd6b20', prediction: '#90cdf4',
  robotPlan: '#3182ce', pinch: '#e53e3e', spike: '#d69e2e', region: '#805ad5',
  corridor: '#d6ebfa', keepOut: '#c53030', corridorRegion: '#2c7a7b', detour: '#9c4221',
  route: '#2f855a',
};
const LEGEND = [['executed', 'executed'], ['deleted', 'deleted'], ['uncovered', 'uncovered'],
  ['plan', 'plan / twin'], ['openLoop', 'open-loop replay'], ['closedLoop', 'closed-loop replay'],
  ['rehearsal', 'rehearsal'], ['robot', 'robot (reported) / its logs'], ['prediction', 'prediction'],
  ['corridor', 'corridor'], ['keepOut', 'keep-out zone'], ['detour', 'detour (robot)'], ['route', 'way to the goals']];

// Everything the page knows (tests read it through window.twindrive).
const S = {
  ws: null, connected: false, everConnected: false, instance: null, reconnects: 0,
  world: null, state: null, plan: null, verify: null, rehearsal: null,
  focus: null, detail: null, regions: [], acked: new Set(), errors: [],
  // The robot's freedom as the operator draws it: keep-out zones and
  // corridor regions ({ kind, name, polygon, half_width_m }), and the
  // polygon being drawn (its vertices).
  zones: [], draft: null,
  // The operator's waypoints for the twin ({ x_m, y_m, heading_rad? }).
  waypoints: [],
  // Refusals the page made itself (nothing was sent), by the part of the
  // page they are shown in; the console's own come with its state.
  local: {}, localSeq: 0,
  // What the last map frame drew of the robots: { id, pose, color }.
  drawn: { robots: [] },
  // Bytes and milliseconds (parse and build) of the heavy messages.
  timings: {},
};
window.twindrive = { S, map, COLORS };

// ---------------------------------------------------------------- link
let backoffMs = 250;
function connect() {
  const proto = location.protocol === 'https:' ? 'wss:' : 'ws:';
  const ws = new WebSocket(`${proto}//${location.host}/ws`);
  S.ws = ws;
  ws.onopen = () => {
    S.connected = true;
    backoffMs = 250;
    setConn(S.everConnected ? 'reconnected' : 'connected', 'ok');
    S.everConnected = true;
    if (S.focus) send({ cmd: 'focus', robot: S.focus });
  };
  ws.onmessage = (e) => {
    const t0 = performance.now();
    let m;
    try { m = JSON.parse(e.data); } catch { return; }
    receive(m);
    if (m.type !== 'state') {
      S.timings[m.type] = { bytes: e.data.length, ms: Math.round(performance.now() - t0) };
    }
  };
  ws.onclose = () => {
    const was = S.connected;
    S.connected = false;
    S.ws = null;
    if (was) S.reconnects++;
    setConn(`console unreachable: reconnecting in ${(backoffMs / 1000).toFixed(1)} s…`, 'bad');
    setTimeout(connect, backoffMs);
    backoffMs = Math.min(backoffMs * 2, 4000);
  };
}

function setConn(text, kind) {
  const c = $('conn');
  c.textContent = text;
  c.className = `pill ${kind}`;
}

function send(obj) {
  if (S.ws && S.ws.readyState === WebSocket.OPEN) {
    S.ws.send(JSON.stringify(obj));
    return true;
  }
  return false;
}

function receive(m) {
  switch (m.type) {
    case 'world':
      S.world = m;
      $('scenario').textContent = `twin: ${m.scenario}`;
      map.setWorld(m);
      break;
    case 'state': onState(m); break;
    case 'plan': onPlan(m); break;
    case 'verify': onVerify(m); break;
    case 'rehearsal': onRehearsal(m); break;
    case 'robot': onDetail(m); break;
    case 'error':
      // A refusal of a control's command is in the console's state (shown
      // beside the control) and its event list; anything else only here.
      S.errors.push(m.message);
      if (!m.logged) {
        addEvent({ seq: `local${S.errors.length}`, level: 'error', text: m.message });
        if (CMD_SPOT[m.cmd]) { S.local[CMD_SPOT[m.cmd]] = m.message; renderRefusals(); }
      }
      break;
  }
}

// ---------------------------------------------------------------- state
function fmt(v, d = 2) { return v === null || v === undefined ? '–' : Number(v).toFixed(d); }
// Degrees in (-180, 180].
function deg(rad) { let d = (rad * 180 / Math.PI) % 360; if (d > 180) d -= 360; if (d <= -180) d += 360; return fmt(d, 0); }
function age(a) { return a === null || a === undefined ? 'never' : `${fmt(a, 1)} s ago`; }

function onState(m) {
  if (S.instance && m.instance !== S.instance) {
    // The console restarted: what it had is gone; it sends its world again.
    S.plan = S.verify = S.rehearsal = S.detail = S.detailLayers = null;
    for (const n of [...map.layers.keys()]) map.setLayer(n, null);
    addEvent({ seq: `restart${m.instance}`, level: 'info', text: 'the console restarted; reconnected to the new one' });
  }
  S.instance = m.instance;
  if (!S.state && m.freedom && !S.zones.length) loadFreedom(m.freedom);
  if (!S.state && m.route?.goals && !S.waypoints.length) loadGoals(m.route.goals);
  S.state = m;
  const t = m.twin;
  $('twin-readout').textContent =
    `twin t=${fmt(t.t_s, 1)} s · (${fmt(t.pose[0])}, ${fmt(t.pose[1])}) m, ${deg(t.pose[2])}° · ${t.drive} · ${t.speed}×` +
    (t.recording_s !== null ? ` · ● REC ${fmt(t.recording_s, 1)} s` : '');
  $('twin-status').textContent = m.job ? `busy: ${m.job}…` : (t.has_rehearsal ? 'rehearsal ready' : 'no rehearsal yet');
  $('btn-record').textContent = t.recording_s !== null ? '■ Stop recording' : '● Record rehearsal';
  $('btn-record').classList.toggle('on', t.recording_s !== null);
  $('btn-wall').classList.toggle('on', t.drive === 'wall_follower');
  if (document.activeElement !== $('speed')) $('speed').value = String(t.speed);
  const p = m.params;
  const params = `plans use wheels ${fmt(p.left_diameter_m, 4)}/${fmt(p.right_diameter_m, 4)} m, wheelbase ${fmt(p.wheelbase_m, 4)} m ` +
    (p.calibrated ? '(calibration; the twin rehearses with them too)' : '');
  const noModel = 'No robot model: plans need the robot\'s calibration. Calibrate it (twindrive calibrate) and start the console with --calibration calib.json.';
  $('btn-plan').disabled = !p.calibrated;
  $('btn-plan').title = p.calibrated ? '' : noModel;
  $('no-model').hidden = p.calibrated;
  $('no-model').textContent = noModel;
  if ($('params').textContent !== params) $('params').textContent = params;
  $('btn-upload').disabled = !(m.can_sign && m.plan && S.focus);
  $('btn-upload').title = m.can_sign ? '' : 'start the console with --key to sign plans';
  renderFleet(m.robots);
  renderRobot(m.robots.find((r) => r.id === S.focus));
  renderBanner(m.robots);
  renderEvents(m.events);
  renderRefusals();
  if (m.verdict) renderVerdict(m.verdict);
  updateCursorRange();
  map.dirty = true;
}

function renderEvents(events) {
  for (const e of events) addEvent(e);
}

function addEvent(e) {
  const list = $('events');
  if (list.querySelector(`[data-seq="${e.seq}"]`)) return;
  const li = document.createElement('li');
  li.dataset.seq = e.seq;
  li.className = e.level;
  li.textContent = e.text;
  list.prepend(li);
  while (list.children.length > 60) list.lastChild.remove();
}

// ---------------------------------------------------------------- fleet
function renderFleet(robots) {
  const body = $('fleet').querySelector('tbody');
  if (!S.focus && robots.length) focus(robots[0].id);
  const rows = robots.map((r) => {
    const link = r.link.outage ? '<span class="stale">outage</span>'
      : `rtt ${r.link.rtt_s === null ? '–' : fmt(r.link.rtt_s, 2) + ' s'}`;
    return `<tr data-id="${esc(r.id)}" class="${r.id === S.focus ? 'focus' : ''}"><td>${esc(r.id)}</td><td>${esc(r.state)}</td><td>${link}</td><td>${planCell(r)}</td></tr>`;
  }).join('');
  if (body.dataset.html !== rows) { body.innerHTML = rows; body.dataset.html = rows; }
}
$('fleet').addEventListener('click', (e) => {
  const tr = e.target.closest('tr[data-id]');
  if (tr) focus(tr.dataset.id);
});

function focus(id) {
  S.focus = id;
  S.detail = null;
  $('focus-name').textContent = id;
  send({ cmd: 'focus', robot: id });
}

// The plan a robot executes or was sent last: its short hash, where the
// robot stands in it (or how far its upload is).
function planCell(r) {
  const p = r.plan;
  if (!p) return '–';
  const name = p.sha256 ? `<code>${esc(p.sha256.slice(0, 12))}</code>` : `transfer <code>${esc(p.transfer.slice(0, 12))}</code>`;
  let where = p.phase;
  if (p.phase === 'uploading' && r.upload) where = `upload ${pct(r.upload)} %`;
  else if (p.passed !== null && p.samples) where = `${p.phase} ${p.passed}/${p.samples}`;
  return `${name} ${esc(where)}`;
}

function pct(u) { return u.chunks ? Math.floor(100 * u.confirmed / u.chunks) : 0; }
function esc(s) { return String(s).replace(/[&<>"]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' })[c]); }

function renderRobot(r) {
  if (!r) return;
  const up = r.upload;
  $('upload-box').hidden = !up;
  if (up) {
    $('upload-progress').value = up.chunks ? up.confirmed / up.chunks : 0;
    $('upload-text').textContent =
      `${pct(up)} % · ${up.confirmed}/${up.chunks} chunks acknowledged · ${up.sent} sent, ${up.resent} resent, ${up.repairs} repair · ` +
      `${(up.bytes / 1000).toFixed(1)} kB in ${fmt(up.elapsed_s, 1)} s` +
      (up.done ? ' · on the robot' : '');
  }
  const l = r.link;
  $('link-state').innerHTML =
    `link: ${l.outage ? '<span class="stale">OUTAGE</span> · ' : ''}round trip ${l.rtt_s === null ? '–' : fmt(l.rtt_s, 2) + ' s'} · ` +
    `last message ${age(l.last_rx_age_s)} · ${fmt(l.rx_msgs_s, 1)} msg/s, ${fmt(l.rx_bytes_s / 1000, 2)} kB/s from the robot · ${l.messages} messages · ` +
    (l.refused ? `<span class="stale">${l.refused} refused (not authentic or replayed)</span> · ` : '') +
    (l.pings_answered + l.pings_lost ? `round-trip loss ${fmt(100 * l.pings_lost / (l.pings_answered + l.pings_lost), 0)} % (${l.pings_lost} of ${l.pings_answered + l.pings_lost} pings)` : 'no ping answered yet');
  const s = r.status;
  if (s) {
    const stale = s.stale ? ' <span class="stale">STALE</span>' : '';
    const pred = r.predicted ? ` · twin predicts (${fmt(r.predicted[0])}, ${fmt(r.predicted[1])})` : '';
    const pose = s.pose ? `pose (${fmt(s.pose[0])}, ${fmt(s.pose[1])}) m, ${deg(s.pose[2])}°` : 'no pose yet';
    const p = r.plan;
    const when = p && p.plan_t_s !== null
      ? ` at ${fmt(p.plan_t_s, 1)} s into plan ${esc((p.sha256 || p.transfer).slice(0, 12))} (${esc(p.phase)})` : '';
    $('robot-status').innerHTML =
      `state <b>${esc(r.state)}</b> · status ${age(s.age_s)}${stale}<br>` +
      `${pose}${when}${pred}<br>` +
      `deviation ${fmt(s.deviation_m, 3)} m (tolerance ${r.tolerances.deviation_m}) · range residual ${fmt(s.range_residual_m, 3)} m (tolerance ${r.tolerances.range_residual_m})<br>` +
      `wheels ${fmt(s.params[0], 4)}/${fmt(s.params[1], 4)} m, wheelbase ${fmt(s.params[2], 4)} m · bumps ${s.bumps} · logs pending ${s.logs_pending}` +
      ' (a plan\'s log comes home as a digest of at most 4 kB per second of plan: within seconds of its end on a fast link, at the link\'s rate once no plan runs)' +
      (s.refused ? ` · <span class="stale">robot refused ${s.refused} message(s)</span>` : '');
  } else {
    $('robot-status').innerHTML = `state <b>${esc(r.state)}</b> · no status from the robot yet`;
  }
  const notes = [];
  const d = S.detail && S.detail.id === r.id ? S.detail : null;
  if (d && d.series.t.length) {
    const stat = (v) => {
      const ok = v.filter((x) => Number.isFinite(x));
      return ok.length ? `mean ${fmt(ok.reduce((a, b) => a + b, 0) / ok.length, 3)}, max ${fmt(Math.max(...ok), 3)} m` : '–';
    };
    notes.push(`discrepancy over ${d.series.t.length} statuses: deviation ${stat(d.series.deviation)}; range residual ${stat(d.series.residual)}`);
  }
  const detours = (d && d.detours) || [];
  const done = detours.filter((x) => x.rejoined);
  if (detours.length) {
    const s = (k) => done.reduce((a, x) => a + x[k], 0);
    notes.push(`${done.length} detour(s) on its own, back on the plan (${fmt(s('extra_s'), 1)} s, ${fmt(s('extra_m'))} m more than the plan)` +
      (detours.length > done.length ? '; going around something now' : ''));
  }
  if (r.learnt.length) notes.push(`the twin learnt ${r.learnt.length} block(s) from the robot`);
  for (const u of (d && d.twin_updates) || []) {
    if (u.params) {
      notes.push(`twin parameters updated: wheels ${fmt(u.params.left_diameter_m, 4)}/${fmt(u.params.right_diameter_m, 4)} m, wheelbase ${fmt(u.params.wheelbase_m, 4)} m`);
    }
  }
  if (r.failure) notes.push(`failure: ${esc(r.failure)}`);
  for (const n of r.notices) notes.push(esc(n));
  $('twin-updates').innerHTML = notes.join('<br>');
}

function renderBanner(robots) {
  const r = robots.find((x) => x.awaiting && !S.acked.has(bannerKey(x)));
  const b = $('banner');
  b.hidden = !r;
  if (!r) return;
  b.dataset.robot = r.id;
  b.dataset.key = bannerKey(r);
  const a = r.awaiting;
  $('banner-text').textContent =
    `Robot ${r.id} handed control back: ${a.reason.replace(/_/g, ' ')} at ${fmt(a.plan_t_s, 1)} s into the plan, at (${fmt(a.pose[0])}, ${fmt(a.pose[1])}).`;
  $('banner-replan').hidden = !a.decision;
  $('banner-end').hidden = false;
}
function bannerKey(r) { return `${r.id}:${r.handbacks}:${r.awaiting.plan_t_s}`; }
$('banner-ack').onclick = () => { S.acked.add($('banner').dataset.key); $('banner').hidden = true; };
$('banner-replan').onclick = () => { act('robot', { cmd: 'replan', robot: $('banner').dataset.robot }); S.acked.add($('banner').dataset.key); };
$('banner-end').onclick = () => { act('robot', { cmd: 'end_mission', robot: $('banner').dataset.robot }); S.acked.add($('banner').dataset.key); };

// ---------------------------------------------------------------- charts
let seriesChart = null, windowChart = null;
function onDetail(d) {
  if (d.id !== S.focus) return;
  S.detail = d;
  const w = Math.max(300, $('robot-panel').clientWidth - 10);
  const sr = d.series;
  const tol = S.state?.robots.find((r) => r.id === d.id)?.tolerances || { deviation_m: 0.15, range_residual_m: 0.1 };
  const data = [sr.t, sr.deviation, sr.residual, sr.t.map(() => tol.deviation_m), sr.t.map(() => tol.range_residual_m)];
  if (!seriesChart) {
    seriesChart = new uPlot({
      title: 'robot vs twin (statuses)', width: w, height: 170,
      scales: { x: { time: false } },
      axes: [{ label: 'console time (s)' }, { label: 'm' }],
      series: [{}, { label: 'deviation', stroke: '#2b6cb0' }, { label: 'range residual', stroke: '#dd6b20' },
        { label: 'deviation tol.', stroke: '#2b6cb0', dash: [4, 4] }, { label: 'residual tol.', stroke: '#dd6b20', dash: [4, 4] }],
    }, data, $('chart-series'));
  } else seriesChart.setData(data);
  if (windowChart) { windowChart.destroy(); windowChart = null; }
  if (d.window && d.window.t.length) {
    const series = [{}];
    const cols = [d.window.t];
    const colors = ['#2b6cb0', '#38a169', '#805ad5', '#d53f8c'];
    d.window.measured.slice(0, 4).forEach((m, b) => {
      cols.push(m); series.push({ label: `measured ${b}`, stroke: colors[b], width: 2 });
      cols.push(d.window.predicted[b]); series.push({ label: `predicted ${b}`, stroke: colors[b], dash: [5, 3] });
    });
    const p0 = d.window.predicted[0] || [];
    cols.push(p0.map((v) => (v === null ? null : v - d.window.tolerance_m)));
    series.push({ label: 'predicted 0 − tolerance', stroke: '#c53030', dash: [2, 3] });
    windowChart = new uPlot({
      title: `hand-back (${d.window.reason}): ranges measured vs predicted`, width: w, height: 170,
      scales: { x: { time: false } }, axes: [{ label: 'plan time (s)' }, { label: 'm' }], series,
    }, cols, $('chart-window'));
  }
  // The robot's plan and its back-filled logs on the map (redrawn only
  // when they change: the statuses come every second).
  const key = `${d.id}:${d.plan_sha256}:${d.logs.length}`;
  if (key !== S.detailLayers) {
    S.detailLayers = key;
    map.setLayer('robot:plan', d.plan ? new LodPath(d.plan) : null, { color: COLORS.robotPlan, width: 1, dash: [6, 4], alpha: 0.8 });
    const band = d.freedom?.corridor_band;
    const own = d.plan_sha256 && d.plan_sha256 !== S.plan?.sha256;
    map.setLayer('corridor:robot', own && band ? new Band(band) : null, { color: COLORS.corridor });
    map.setVisible('corridor', map.isVisible('corridor'));
    for (const n of [...map.layers.keys()]) if (n.startsWith('robot:log')) map.setLayer(n, null);
    d.logs.forEach((l, i) => map.setLayer(`robot:log${i}`, new LodPath(l), { color: COLORS.robot, width: 2 }));
  }
  updateCursorRange();
}

// ---------------------------------------------------------------- plan
function onPlan(p) {
  S.plan = p;
  const ex = p.executed;
  const deleted = p.deletions.map((d) => [Math.max(0, d.first - 1), d.last + 1]);
  const uncovered = p.uncovered.map((u) => [u.first, u.last]);
  map.setLayer('executed', new LodPath(ex), { color: COLORS.executed, width: 1.5 });
  map.setLayer('deleted', deleted.length ? new LodPath(ex, deleted) : null, { color: COLORS.deleted, width: 2.5, alpha: 0.8 });
  map.setLayer('uncovered', uncovered.length ? new LodPath(ex, uncovered) : null, { color: COLORS.uncovered, width: 4 });
  map.setLayer('plan', new LodPath(p.plan), { color: COLORS.plan, width: 2 });
  const band = p.freedom.corridor_band;
  map.setLayer('corridor', band ? new Band(band) : null, { color: COLORS.corridor });
  for (const g of ['executed', 'deleted', 'uncovered', 'plan', 'corridor']) map.setVisible(g, map.isVisible(g));
  const s = p.summary;
  $('plan-summary').innerHTML =
    `plan <code>${p.sha256.slice(0, 12)}</code>: <b>${fmt(s.plan_length_m)} m in ${fmt(s.plan_duration_s, 1)} s</b> ` +
    `from ${fmt(s.executed_length_m)} m in ${fmt(s.executed_duration_s, 1)} s rehearsed · ` +
    `<b>${fmt(s.coverage_percent, 2)} %</b> of the route within ${fmt(s.coverage_radius_m)} m (${fmt(s.uncovered_m, 3)} m uncovered) · ` +
    `${s.loops_removed} loop(s), ${s.kinks_removed} kink(s), ${fmt(s.trailing_retrace_m)} m trailing retrace cut · ` +
    `${s.refused_cuts} cut(s) refused (they would drop ground) · ${s.spikes_found} spike(s) filtered in ${s.filter_windows} window(s) · ${p.samples} samples · ` +
    freedomLine(p.freedom) + goalsLine(p.goals);
  $('verdict').textContent = '';
  map.setLayer('replays:open', null);
  map.setLayer('replays:closed', null);
  updateCursorRange();
}

// The operator's goals the plan keeps, in words (nothing for a manual
// rehearsal).
function goalsLine(g) {
  if (!g || (!(g.waypoints || []).length && !(g.areas || []).length)) return '';
  const ways = (g.waypoints || []).map((w) =>
    `${esc(w.name)} within ${fmt(w.passed_m, 3)} m` +
    (w.heading_error_rad != null ? `, facing within ${fmt(w.heading_error_rad, 3)} rad` : '') +
    (w.dwell_s > 0 ? `, standing ${fmt(w.stood_s, 1)} of ${fmt(w.dwell_s, 1)} s` : ''));
  const areas = (g.areas || []).map((a) => `${esc(a.name)} swept ${fmt(a.swept_percent, 1)} %`);
  return ` · <span id="plan-goals">goals kept: ${ways.concat(areas).join('; ')}</span>`;
}

// The freedom a plan was signed with, in words.
function freedomLine(f) {
  const w = f.corridor_half_width_m;
  const corridor = w && w.length
    ? `corridor ${fmt(Math.min(...w))}–${fmt(Math.max(...w))} m each side in ${f.stretches} stretch(es)`
    : 'no corridor (the robot hands back on anything unexpected)';
  return `${corridor}, ${f.keep_out.length} keep-out zone(s); detours may add ${fmt(f.max_extra_time_s, 0)} s in all, ${fmt(f.max_extra_distance_m, 1)} m each`;
}

function onVerify(v) {
  S.verify = v;
  map.setLayer('replays:open', new LodPath(v.open_loop), { color: COLORS.openLoop, width: 1.5, dash: [6, 3] });
  map.setLayer('replays:closed', new LodPath(v.closed_loop), { color: COLORS.closedLoop, width: 1.5 });
  map.setVisible('replays', map.isVisible('replays'));
  renderVerdict(v.verdict);
}

function renderVerdict(v) {
  const esc = (t) => String(t).replace(/[&<>]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;' }[c]));
  const reasons = (v.reasons || []).map((r) => `<li>${esc(r)}</li>`).join('');
  $('verdict').innerHTML = `verification: <span class="pill ${v.passed ? 'ok' : 'bad'}">${v.passed ? 'passed' : 'FAILED'}</span> ` +
    `open loop ${v.open_loop.collisions} collisions, ${v.open_loop.bumps} bumps, ${fmt(v.open_loop.max_deviation_m, 3)} m max deviation; ` +
    `closed loop ${v.closed_loop.collisions} collisions, ${v.closed_loop.bumps} bumps, ${fmt(v.closed_loop.max_deviation_m, 3)} m max deviation ` +
    `(tolerance ${fmt(v.max_deviation_tolerance_m, 3)} m)` +
    (v.passed ? '' : `<ul class="reasons">${reasons}</ul><b>This plan is not sent</b> unless you tick “send even if verification failed”.`);
  $('verdict').classList.toggle('failed', !v.passed);
}

function onRehearsal(r) {
  S.rehearsal = r;
  map.setLayer('rehearsal', new LodPath(r.track), { color: COLORS.rehearsal, width: 1, alpha: 0.5 });
  map.setVisible('rehearsal', map.isVisible('rehearsal'));
  updateCursorRange();
}

for (const box of document.querySelectorAll('input[data-layer]')) {
  box.addEventListener('change', () => {
    map.setVisible(box.dataset.layer, box.checked);
  });
}

// What the plan command carries of the redundancy settings; a
// `refused` reason, in words, when the inputs do not say numbers.
function redundancySettings() {
  const pinch = parseFloat($('pinch').value);
  const cov = $('coverage').value.trim();
  if (!(pinch > 0)) return { refused: 'the pinch distance: a number of metres above 0, please' };
  if (cov !== '' && !(parseFloat(cov) > 0)) return { refused: 'the coverage radius: a number of metres above 0, or empty for the pinch distance' };
  const texts = $('keep-windows').value.split(',').map((w) => w.trim()).filter(Boolean);
  const windows = texts.map((w) => {
    const m = w.match(/^(-?[\d.]+)\s*-\s*(-?[\d.]+)$/);
    return m ? { start_s: Number(m[1]), end_s: Number(m[2]) } : { start_s: NaN, end_s: NaN };
  });
  const bad = windows.findIndex((w) => !(Number.isFinite(w.start_s) && Number.isFinite(w.end_s) && w.end_s > w.start_s));
  if (bad >= 0) return { refused: `keep times: “${texts[bad]}” is not a window; write them as 10-20, 45-50 (seconds from the rehearsal's start, the end after the start)` };
  const r = {
    pinch_distance_m: pinch,
    reversing_is_redundant: $('cut-reversing').checked,
    keep_end: $('keep-end').checked,
    keep_regions: S.regions,
    keep_windows: windows,
  };
  if (cov !== '') r.coverage_radius_m = parseFloat(cov);
  return { settings: r };
}

function renderRegions() {
  $('regions').innerHTML = S.regions.map((r, i) =>
    `<li>circle (${fmt(r.x_m)}, ${fmt(r.y_m)}) r ${fmt(r.radius_m)} m <button data-i="${i}">remove</button></li>`).join('');
  map.dirty = true;
}
$('regions').addEventListener('click', (e) => {
  const i = e.target.dataset.i;
  if (i !== undefined) { S.regions.splice(Number(i), 1); renderRegions(); }
});

// ---------------------------------------------------------------- freedom
// Keep-out zones (the robot never enters them) and corridor regions (the
// corridor's half width where the plan's path runs inside one), signed
// with the plan. Drawing: a drag makes a rectangle; clicks make a polygon,
// closed by a click on its first or last vertex or by Enter (Escape drops
// it). Outside a drawing mode a vertex can be dragged.
const CLOSE_PX = 10;

function pickVertex(mode, a, b) {
  const px = 1 / map.scale;
  const kind = { zone: 'keep_out', corridor: 'corridor', sweep: 'sweep' }[mode];
  if (!S.draft && Math.hypot(b[0] - a[0], b[1] - a[1]) > CLOSE_PX * px) {
    addZone(kind, [[a[0], a[1]], [b[0], a[1]], [b[0], b[1]], [a[0], b[1]]]);
    setMode(null);
    return;
  }
  if (!S.draft) S.draft = { kind, polygon: [] };
  const v = S.draft.polygon;
  const near = (p) => p && Math.hypot(p[0] - b[0], p[1] - b[1]) <= CLOSE_PX * px;
  if (v.length >= 3 && (near(v[0]) || near(v[v.length - 1]))) {
    finishDraft();
    setMode(null);
    return;
  }
  if (!near(v[v.length - 1])) v.push([b[0], b[1]]);
  map.dirty = true;
}

// Closes the polygon being drawn (dropped with fewer than three vertices).
function finishDraft() {
  const d = S.draft;
  S.draft = null;
  if (d && d.polygon.length >= 3) addZone(d.kind, d.polygon);
  map.dirty = true;
}

function addZone(kind, polygon) {
  const word = { keep_out: 'zone', corridor: 'corridor region', sweep: 'area' }[kind];
  let k = 1;
  while (S.zones.some((z) => z.name === `${word} ${k}`)) k++;
  const half = parseFloat($('corridor-width').value);
  S.zones.push({ kind, name: `${word} ${k}`, polygon, half_width_m: Number.isFinite(half) ? half : 0.5 });
  renderZones();
}

// Shoelace area (m^2).
function area(poly) {
  let a = 0;
  for (let i = 0; i < poly.length; i++) {
    const [x0, y0] = poly[i], [x1, y1] = poly[(i + 1) % poly.length];
    a += x0 * y1 - x1 * y0;
  }
  return Math.abs(a) / 2;
}

function renderZones() {
  $('zones').innerHTML = S.zones.map((z, i) => {
    const what = { keep_out: 'keep out', corridor: 'corridor', sweep: 'to sweep' }[z.kind];
    const width = z.kind === 'corridor'
      ? ` half width <input data-i="${i}" data-f="half_width_m" type="number" step="0.05" min="0.05" value="${z.half_width_m}"> m` : '';
    return `<li data-kind="${z.kind}"><input data-i="${i}" data-f="name" value="${esc(z.name)}" size="10"> ${what}, ` +
      `${z.polygon.length} vertices, ${fmt(area(z.polygon))} m²${width} <button data-remove="${i}">remove</button></li>`;
  }).join('');
  map.dirty = true;
}
$('zones').addEventListener('click', (e) => {
  const i = e.target.dataset.remove;
  if (i !== undefined) { S.zones.splice(Number(i), 1); renderZones(); }
});
$('zones').addEventListener('change', (e) => {
  const { i, f } = e.target.dataset;
  if (i === undefined) return;
  const z = S.zones[Number(i)];
  z[f] = f === 'name' ? e.target.value.trim() : parseFloat(e.target.value);
  renderZones();
});

// A press within a few pixels of a vertex drags it.
map.grab = (w, px) => {
  for (const z of S.zones) {
    for (let j = 0; j < z.polygon.length; j++) {
      const [x, y] = z.polygon[j];
      if (Math.hypot(x - w[0], y - w[1]) <= CLOSE_PX * px) {
        return (to) => { z.polygon[j] = [to[0], to[1]]; renderZones(); };
      }
    }
  }
  return null;
};

// What the plan command carries; a bound left empty keeps its default.
function freedomSettings() {
  const f = {
    keep_out: S.zones.filter((z) => z.kind === 'keep_out').map((z) => ({ name: z.name, polygon: z.polygon })),
    corridor: S.zones.filter((z) => z.kind === 'corridor').map((z) => ({ region: z.polygon, half_width_m: z.half_width_m })),
  };
  const time = parseFloat($('max-extra-time').value), dist = parseFloat($('max-extra-distance').value);
  if (Number.isFinite(time)) f.max_extra_time_s = time;
  if (Number.isFinite(dist)) f.max_extra_distance_m = dist;
  return f;
}

// Why the freedom's inputs say no numbers, in words; null when they do.
function freedomProblem() {
  const corridor = S.zones.filter((z) => z.kind === 'corridor');
  const bad = corridor.find((z) => !Number.isFinite(z.half_width_m));
  if (bad) return `the half width of the corridor region '${bad.name}': a number of metres, please`;
  for (const [id, what] of [['max-extra-time', 'the time detours may add in all (s)'], ['max-extra-distance', 'the distance a detour may add (m)']]) {
    const e = $(id);
    if (e.validity.badInput || (e.value !== '' && !Number.isFinite(parseFloat(e.value)))) return `${what}: a number, please`;
  }
  return null;
}

// The console's last freedom settings (a page opened later takes them up).
function loadFreedom(f) {
  S.zones = [
    ...f.keep_out.map((z) => ({ kind: 'keep_out', name: z.name, polygon: z.polygon, half_width_m: 0.5 })),
    ...f.corridor.map((c, i) => ({ kind: 'corridor', name: `corridor region ${i + 1}`, polygon: c.region, half_width_m: c.half_width_m })),
  ];
  $('max-extra-time').value = String(f.max_extra_time_s);
  $('max-extra-distance').value = String(f.max_extra_distance_m);
  renderZones();
}

function drawZones(ctx, px, zones, dashed) {
  ctx.lineWidth = 2 * px;
  ctx.setLineDash(dashed ? [6 * px, 4 * px] : []);
  for (const z of zones) {
    ctx.beginPath();
    z.polygon.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.closePath();
    ctx.fillStyle = { keep_out: 'rgba(197, 48, 48, 0.18)', corridor: 'rgba(44, 122, 123, 0.10)', sweep: 'rgba(47, 133, 90, 0.12)' }[z.kind];
    ctx.strokeStyle = { keep_out: COLORS.keepOut, corridor: COLORS.corridorRegion, sweep: COLORS.route }[z.kind];
    ctx.fill();
    ctx.stroke();
    if (!dashed) for (const [x, y] of z.polygon) ctx.strokeRect(x - 3 * px, y - 3 * px, 6 * px, 6 * px);
  }
  ctx.setLineDash([]);
}

// A robot's detours: the way it planned from where it left the plan, and
// the points where its readings ended on what the map lacked.
function drawDetours(ctx, px, detours) {
  for (const d of detours) {
    ctx.strokeStyle = COLORS.detour;
    ctx.lineWidth = 2.5 * px;
    ctx.setLineDash(d.rejoined ? [] : [5 * px, 3 * px]);
    ctx.beginPath();
    ctx.moveTo(d.from[0], d.from[1]);
    for (const [x, y] of d.waypoints) ctx.lineTo(x, y);
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.fillStyle = COLORS.detour;
    ctx.beginPath(); ctx.arc(d.from[0], d.from[1], 4 * px, 0, 2 * Math.PI); ctx.fill();
  }
}

// ---------------------------------------------------------------- goals
// Waypoints for the twin: the console plans the way from where the twin's
// robot stands (out of the keep-out zones drawn above) and, asked to,
// drives it, recording the rehearsal, which ends at the last waypoint.
function renderWaypoints() {
  $('waypoints').innerHTML = S.waypoints.map((w, i) =>
    `<li>(${fmt(w.x_m)}, ${fmt(w.y_m)})${w.heading_rad === undefined ? '' : `, facing ${deg(w.heading_rad)}°`} ` +
    `<button data-i="${i}">remove</button></li>`).join('');
  map.dirty = true;
}
$('waypoints').addEventListener('click', (e) => {
  const i = e.target.dataset.i;
  if (i !== undefined) { S.waypoints.splice(Number(i), 1); renderWaypoints(); }
});
// Clear: the waypoints and areas go, and the console forgets the way (or
// why there was none), so no page shows it again.
$('btn-goals-clear').onclick = () => {
  S.waypoints = [];
  S.zones = S.zones.filter((z) => z.kind !== 'sweep');
  renderWaypoints();
  renderZones();
  act('goals', { cmd: 'goals_clear' });
};
function goals(drive) {
  if (map.mode === 'waypoint') setMode(null);
  const goals = {
    waypoints: S.waypoints,
    areas: S.zones.filter((z) => z.kind === 'sweep').map((z) => ({ polygon: z.polygon })),
  };
  const clearance = parseFloat($('goal-clearance').value), speed = parseFloat($('goal-speed').value);
  if (!Number.isFinite(clearance)) return refuse('goals', 'the clearance: a number of metres, please');
  if (!Number.isFinite(speed)) return refuse('goals', 'the speed: a number of metres a second, please');
  goals.clearance_m = clearance;
  goals.speed_m_s = speed;
  if ($('goal-home').checked) goals.return_home = true;
  act('goals', { cmd: 'goals', drive, goals, keep_out: freedomSettings().keep_out });
}
$('btn-route').onclick = () => goals(false);
$('btn-drive-route').onclick = () => goals(true);

// The goals the console's way was planned to (a page opened later takes
// them up, as it takes up the freedom).
function loadGoals(g) {
  S.waypoints = (g.waypoints || []).map((w) => {
    const o = { x_m: w.x_m, y_m: w.y_m };
    if (w.heading_rad !== null && w.heading_rad !== undefined) o.heading_rad = w.heading_rad;
    if (w.dwell_s) o.dwell_s = w.dwell_s;
    if (w.speed_m_s !== null && w.speed_m_s !== undefined) o.speed_m_s = w.speed_m_s;
    return o;
  });
  (g.areas || []).forEach((a, i) => S.zones.push({ kind: 'sweep', name: `area ${i + 1}`, polygon: a.polygon, half_width_m: 0.5 }));
  $('goal-clearance').value = String(g.clearance_m);
  $('goal-speed').value = String(g.speed_m_s);
  $('goal-home').checked = !!g.return_home;
  renderWaypoints();
  renderZones();
}

// The way to the goals, or the refusal of the last goals (beside the
// buttons that sent them).
function renderRoute(r, refusal) {
  const text = refusal
    ? `${r && r.unreachable ? 'no way' : 'refused'}: ${refusal.replace(/^goals: /, '')}`
    : !r || r.unreachable ? ''
    : `way: ${fmt(r.length_m)} m through ${r.waypoints.length} stop(s), about ${fmt(r.duration_s, 0)} s, the footprint at least ${fmt(r.min_clearance_m, 3)} m clear` +
      (r.areas || []).map((a, i) => `; area ${i + 1}: ${a.lanes} lane(s), ${a.touch_ups} touch-up(s), ${fmt(a.planned_percent, 1)} % of ${fmt(a.free_m2)} m² swept as planned` +
        (a.swept_percent !== undefined ? `, ${fmt(a.swept_percent, 1)} % swept by the twin` : '')).join('');
  if ($('route-status').textContent !== text) $('route-status').textContent = text;
  $('route-status').classList.toggle('warn', !!refusal);
}

// ---------------------------------------------------------------- refusals
// Each part of the page shows the last refusal of what it sent, in the
// operator's words, until a command from there succeeds; the event list
// keeps them all. The console's are in its state (a page opened later
// shows them too); the page's own (inputs that say no number) are local.
const SPOTS = { twin: 'refusal-twin', plan: 'refusal-plan', freedom: 'refusal-freedom', robot: 'refusal-robot' };
const CMD_SPOT = {
  goals: 'goals', goals_clear: 'goals', plan: 'plan', verify: 'plan', upload: 'robot', replan: 'robot',
  end_mission: 'robot', wall_follow: 'twin', speed: 'twin', reset: 'twin', place: 'twin', record_start: 'twin', record_stop: 'twin',
};
function renderRefusals() {
  const r = S.state?.refusals || {};
  for (const [spot, id] of Object.entries(SPOTS)) {
    const text = S.local[spot] ?? r[spot] ?? '';
    if ($(id).textContent !== text) $(id).textContent = text;
  }
  renderRoute(S.state?.route, S.local.goals ?? r.goals);
}

// A refusal the page makes itself: nothing is sent.
function refuse(spot, text) {
  S.local[spot] = text;
  addEvent({ seq: `page${++S.localSeq}`, level: 'error', text });
  renderRefusals();
}

// Sends a command from a part of the page; the page's own refusal there
// goes (the console's goes once the command succeeds).
function act(spot, cmd) {
  delete S.local[spot];
  renderRefusals();
  send(cmd);
}

// The waypoints (numbered, with their headings), the way planned to them,
// or where it is blocked.
function drawGoals(ctx, px) {
  const r = S.state?.route;
  if (r && r.points) {
    ctx.strokeStyle = COLORS.route;
    ctx.lineWidth = 2.5 * px;
    ctx.setLineDash([8 * px, 4 * px]);
    ctx.beginPath();
    r.points.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.stroke();
    ctx.setLineDash([]);
  }
  if (r && r.unreachable && r.unreachable.blocked_at) {
    const u = r.unreachable, [bx, by] = u.blocked_at, d = 6 * px;
    ctx.strokeStyle = COLORS.bumped;
    ctx.lineWidth = 3 * px;
    ctx.beginPath(); ctx.moveTo(bx - d, by - d); ctx.lineTo(bx + d, by + d); ctx.moveTo(bx - d, by + d); ctx.lineTo(bx + d, by - d); ctx.stroke();
    ctx.setLineDash([4 * px, 4 * px]);
    ctx.beginPath(); ctx.moveTo(u.nearest[0], u.nearest[1]); ctx.lineTo(u.at[0], u.at[1]); ctx.stroke();
    ctx.setLineDash([]);
  }
  S.waypoints.forEach((w, i) => {
    ctx.fillStyle = COLORS.route;
    ctx.beginPath(); ctx.arc(w.x_m, w.y_m, 7 * px, 0, 2 * Math.PI); ctx.fill();
    if (w.heading_rad !== undefined) {
      ctx.strokeStyle = COLORS.route; ctx.lineWidth = 2 * px;
      ctx.beginPath(); ctx.moveTo(w.x_m, w.y_m);
      ctx.lineTo(w.x_m + 18 * px * Math.cos(w.heading_rad), w.y_m + 18 * px * Math.sin(w.heading_rad)); ctx.stroke();
    }
    label(ctx, px, [w.x_m - 16 * px, w.y_m - 16 * px], String(i + 1));
  });
}

// ---------------------------------------------------------------- controls
$('btn-wall').onclick = () => act('twin', { cmd: 'wall_follow' });
$('btn-stop').onclick = () => send({ cmd: 'stop' });
$('btn-reset').onclick = () => act('twin', { cmd: 'reset' });
$('speed').onchange = () => act('twin', { cmd: 'speed', factor: parseFloat($('speed').value) });
$('btn-record').onclick = () => act('twin', { cmd: S.state?.twin.recording_s !== null && S.state ? 'record_stop' : 'record_start' });
$('btn-plan').onclick = () => {
  if (S.draft) finishDraft();
  delete S.local.freedom;
  const r = redundancySettings();
  if (r.refused) return refuse('plan', r.refused);
  const problem = freedomProblem();
  if (problem) return refuse('freedom', problem);
  act('plan', { cmd: 'plan', redundancy: r.settings, freedom: freedomSettings() });
};
$('btn-verify').onclick = () => act('plan', { cmd: 'verify' });
$('btn-upload').onclick = () => {
  if (S.focus) act('robot', { cmd: 'upload', robot: S.focus, force: $('force-upload').checked });
};
function setMode(mode) {
  if (S.draft) finishDraft();
  map.mode = map.mode === mode ? null : mode;
  $('btn-place').classList.toggle('on', map.mode === 'place');
  $('btn-region').classList.toggle('on', map.mode === 'region');
  $('btn-zone').classList.toggle('on', map.mode === 'zone');
  $('btn-waypoint').classList.toggle('on', map.mode === 'waypoint');
  $('btn-sweep').classList.toggle('on', map.mode === 'sweep');
  $('btn-corridor').classList.toggle('on', map.mode === 'corridor');
  $('map').className = map.mode || '';
}
$('btn-place').onclick = () => setMode('place');
$('btn-region').onclick = () => setMode('region');
$('btn-zone').onclick = () => setMode('zone');
$('btn-corridor').onclick = () => setMode('corridor');
$('btn-waypoint').onclick = () => setMode('waypoint');
$('btn-sweep').onclick = () => setMode('sweep');
map.onPick = (mode, a, b) => {
  if (mode === 'place') {
    const heading = Math.hypot(b[0] - a[0], b[1] - a[1]) > 0.05 ? Math.atan2(b[1] - a[1], b[0] - a[0]) : 0;
    act('twin', { cmd: 'place', x_m: a[0], y_m: a[1], heading_rad: heading });
  } else if (mode === 'region') {
    const r = Math.hypot(b[0] - a[0], b[1] - a[1]);
    if (r > 0.02) S.regions.push({ kind: 'circle', x_m: a[0], y_m: a[1], radius_m: r });
    renderRegions();
  } else if (mode === 'zone' || mode === 'corridor' || mode === 'sweep') {
    pickVertex(mode, a, b);
    return; // the mode stays until the polygon is closed
  } else if (mode === 'waypoint') {
    const w = { x_m: a[0], y_m: a[1] };
    if (Math.hypot(b[0] - a[0], b[1] - a[1]) > CLOSE_PX / map.scale) w.heading_rad = Math.atan2(b[1] - a[1], b[0] - a[0]);
    S.waypoints.push(w);
    renderWaypoints();
    return; // more clicks add more, until the button is pressed again
  }
  setMode(null);
};

// Keys: arrows or WASD, renewed every 100 ms while held (the console's
// dead-man lapses 0.4 s after the last); a stop on release.
const held = new Set();
const KEYS = { ArrowUp: 'f', KeyW: 'f', ArrowDown: 'b', KeyS: 'b', ArrowLeft: 'l', KeyA: 'l', ArrowRight: 'r', KeyD: 'r' };
function typing(e) { return ['INPUT', 'SELECT', 'TEXTAREA'].includes(e.target.tagName); }
window.addEventListener('keydown', (e) => {
  if (!typing(e) && (e.key === 'Enter' || e.key === 'Escape') && (S.draft || map.mode)) {
    if (e.key === 'Escape') S.draft = null;
    setMode(null); // closes a polygon being drawn
    e.preventDefault();
    return;
  }
  const k = KEYS[e.code];
  if (!k || typing(e)) return;
  e.preventDefault();
  if (!held.has(k)) { held.add(k); sendKeys(); }
});
window.addEventListener('keyup', (e) => {
  const k = KEYS[e.code];
  if (!k) return;
  held.delete(k);
  if (held.size === 0) send({ cmd: 'stop' }); else sendKeys();
});
window.addEventListener('blur', () => { if (held.size) { held.clear(); send({ cmd: 'stop' }); } });
function sendKeys() {
  const forward = (held.has('f') ? 1 : 0) - (held.has('b') ? 1 : 0);
  const turn = (held.has('l') ? 1 : 0) - (held.has('r') ? 1 : 0);
  send({ cmd: 'drive', forward, turn });
}
setInterval(() => { if (held.size) sendKeys(); }, 100);

// The joystick: drive while held, stop when released (a dead-man).
const pad = $('joystick'), stick = $('stick');
let joy = null;
pad.addEventListener('pointerdown', (e) => { pad.setPointerCapture(e.pointerId); joy = [0, 0]; moveJoy(e); });
pad.addEventListener('pointermove', (e) => { if (joy) moveJoy(e); });
const release = () => { if (!joy) return; joy = null; stick.style.left = stick.style.top = '40px'; send({ cmd: 'stop' }); };
pad.addEventListener('pointerup', release);
pad.addEventListener('pointercancel', release);
function moveJoy(e) {
  const r = pad.getBoundingClientRect();
  let dx = (e.clientX - r.left - r.width / 2) / (r.width / 2);
  let dy = (e.clientY - r.top - r.height / 2) / (r.height / 2);
  const n = Math.hypot(dx, dy);
  if (n > 1) { dx /= n; dy /= n; }
  joy = [-dy, -dx];
  stick.style.left = `${40 + dx * 40}px`;
  stick.style.top = `${40 + dy * 40}px`;
  send({ cmd: 'drive', forward: round(joy[0]), turn: round(joy[1]) });
}
function round(v) { return Math.round(v * 100) / 100; }
setInterval(() => { if (joy) send({ cmd: 'drive', forward: round(joy[0]), turn: round(joy[1]) }); }, 100);

// ---------------------------------------------------------------- look back
function updateCursorRange() {
  let max = 0;
  const end = (c) => (c && c.t.length ? c.t[c.t.length - 1] : 0);
  max = Math.max(max, end(S.rehearsal?.track), end(S.plan?.plan ? rel(S.plan.plan) : null));
  for (const l of S.detail?.logs || []) max = Math.max(max, end(l));
  $('cursor').max = String(Math.ceil(max));
}
function rel(c) { return { t: c.t.map((t) => t - c.t[0]), x: c.x, y: c.y }; }
$('cursor').oninput = () => { $('cursor-on').checked = true; map.dirty = true; };
$('cursor-on').onchange = () => { map.dirty = true; };

// ---------------------------------------------------------------- overlay
map.overlay = (ctx, px) => {
  const st = S.state;
  // Keep regions.
  ctx.fillStyle = 'rgba(128, 90, 213, 0.15)';
  ctx.strokeStyle = COLORS.region;
  ctx.lineWidth = 1.5 * px;
  for (const r of S.regions) { ctx.beginPath(); ctx.arc(r.x_m, r.y_m, r.radius_m, 0, 2 * Math.PI); ctx.fill(); ctx.stroke(); }
  // The robot's freedom: the zones being drawn, the one in progress, and
  // (dashed) those the focused robot's plan was signed with.
  if (map.isVisible('zones')) {
    drawZones(ctx, px, S.zones, false);
    if (S.draft) {
      ctx.strokeStyle = S.draft.kind === 'keep_out' ? COLORS.keepOut : COLORS.corridorRegion;
      ctx.lineWidth = 2 * px;
      ctx.beginPath();
      S.draft.polygon.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
      ctx.stroke();
      for (const [x, y] of S.draft.polygon) ctx.strokeRect(x - 3 * px, y - 3 * px, 6 * px, 6 * px);
    }
    const signed = S.detail?.freedom?.keep_out || [];
    drawZones(ctx, px, signed.map((z) => ({ kind: 'keep_out', polygon: z.polygon })), true);
  }
  if (S.detail?.detours && map.isVisible('detours')) drawDetours(ctx, px, S.detail.detours);
  drawGoals(ctx, px);
  if (S.plan && map.isVisible('pinches')) {
    ctx.strokeStyle = COLORS.pinch;
    ctx.lineWidth = 1.5 * px;
    for (const [x0, y0, x1, y1] of S.plan.pinches) {
      ctx.beginPath(); ctx.arc(x0, y0, 5 * px, 0, 2 * Math.PI); ctx.stroke();
      ctx.beginPath(); ctx.arc(x1, y1, 5 * px, 0, 2 * Math.PI); ctx.stroke();
      ctx.setLineDash([3 * px, 3 * px]); ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke(); ctx.setLineDash([]);
    }
  }
  if (S.plan && map.isVisible('spikes')) {
    ctx.strokeStyle = COLORS.spike;
    ctx.lineWidth = 2 * px;
    for (const [x, y] of S.plan.spikes) {
      const d = 4 * px;
      ctx.beginPath(); ctx.moveTo(x - d, y - d); ctx.lineTo(x + d, y + d); ctx.moveTo(x - d, y + d); ctx.lineTo(x + d, y - d); ctx.stroke();
    }
  }
  if (!st) return;
  // Learnt blocks of the focused robot's twin.
  const focused = st.robots.find((r) => r.id === S.focus);
  if (focused) {
    ctx.fillStyle = 'rgba(197, 48, 48, 0.55)';
    for (const [a, b] of focused.learnt) ctx.fillRect(a[0], a[1], b[0] - a[0], b[1] - a[1]);
  }
  const fr = S.world ? S.world.footprint_radius_m : 0.15;
  // The twin's robot: beams, footprint, heading, bumps.
  const t = st.twin;
  ctx.lineWidth = 1 * px;
  ctx.strokeStyle = 'rgba(214, 158, 46, 0.8)';
  ctx.beginPath();
  for (const [x0, y0, x1, y1] of t.beams) { ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); }
  ctx.stroke();
  robotGlyph(ctx, px, t.pose, fr, t.bump ? COLORS.bumped : COLORS.twin, 1);
  ctx.fillStyle = COLORS.bumped;
  for (const [x, y] of t.bumps) { ctx.beginPath(); ctx.arc(x, y, 3 * px, 0, 2 * Math.PI); ctx.fill(); }
  // Every robot that reported a pose: that pose (faded when stale), and
  // the twin's prediction for the same plan time.
  const drawn = [];
  for (const r of st.robots) {
    if (r.predicted) robotGlyph(ctx, px, r.predicted, fr, COLORS.prediction, 0.7, true);
    if (r.status && r.status.pose) {
      robotGlyph(ctx, px, r.status.pose, fr, COLORS.robot, r.status.stale ? 0.35 : 1);
      label(ctx, px, r.status.pose, `${r.id} · ${fmt(r.status.age_s, 1)} s${r.status.stale ? ' STALE' : ''}`);
      drawn.push({ id: r.id, pose: r.status.pose, color: COLORS.robot });
    }
  }
  S.drawn = { robots: drawn };
  // The time cursor: the rehearsal, the plan and the robot's log at t.
  if ($('cursor-on').checked) {
    const tc = parseFloat($('cursor').value);
    $('cursor-label').textContent = `t = ${tc.toFixed(1)} s`;
    const marks = [];
    if (S.rehearsal) marks.push([at(S.rehearsal.track, tc), COLORS.rehearsal]);
    if (S.plan) marks.push([at(rel(S.plan.plan), tc), COLORS.plan]);
    for (const l of S.detail?.logs || []) marks.push([at(l, tc), COLORS.robot]);
    for (const [p, color] of marks) {
      if (!p) continue;
      ctx.strokeStyle = color; ctx.lineWidth = 2.5 * px;
      ctx.beginPath(); ctx.arc(p[0], p[1], 7 * px, 0, 2 * Math.PI); ctx.stroke();
    }
  }
};

function robotGlyph(ctx, px, pose, radius, color, alpha, dashed) {
  const [x, y, h] = pose;
  ctx.globalAlpha = alpha;
  ctx.strokeStyle = color;
  ctx.lineWidth = 2 * px;
  ctx.setLineDash(dashed ? [4 * px, 3 * px] : []);
  ctx.beginPath(); ctx.arc(x, y, radius, 0, 2 * Math.PI); ctx.stroke();
  ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(x + radius * Math.cos(h), y + radius * Math.sin(h)); ctx.stroke();
  ctx.setLineDash([]);
  ctx.globalAlpha = 1;
}

function label(ctx, px, pose, text) {
  ctx.save();
  ctx.translate(pose[0], pose[1]);
  ctx.scale(px, -px);
  ctx.fillStyle = '#1d1d1f';
  ctx.font = '11px system-ui, sans-serif';
  ctx.fillText(text, 12, -12);
  ctx.restore();
}

$('legend').innerHTML = LEGEND
  .map(([k, n]) => `<span data-key="${k}"><i style="background:${COLORS[k]}"></i>${n}</span>`).join('');

// The token came in the address; the cookie carries it from here on.
if (location.search.includes('token=')) history.replaceState(null, '', location.pathname);
connect();
