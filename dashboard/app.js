// The dashboard's logic: polls /v1/stats every couple of seconds and redraws the tiles, four
// Chart.js charts, the replicas and recent jobs of the service, and the thumbnails of recent
// renders. History (throughput and backlog over time) lives in the page: the server keeps only
// the recent jobs. Behind a load balancer each poll may reach another replica: everything
// drawn is the service's, but the engine's tiles (cache, pools, resets) and the header name the
// replica that answered.
"use strict";

const POLL_MS = 2000;
const HISTORY_POINTS = 150; // five minutes at one poll every two seconds
const PHASE_COLOURS = ["#f0b429", "#3fb950", "#58a6ff", "#d2a8ff", "#ff7b72", "#79c0ff", "#ffa657", "#a5d6ff", "#7ee787", "#e3b341"];

Chart.defaults.color = "#8b949e";
Chart.defaults.borderColor = "#2a313b";
Chart.defaults.animation = false; // redrawn every poll; animation would only blur the screenshot
Chart.defaults.maintainAspectRatio = false;

const history = { labels: [], throughput: [], queued: [], running: [] };
let polls = 0;

// A server started with --auth-token-file wants a bearer token: taken once from the URL
// fragment (`/#token=…`, never sent to the server in the URL) and kept for this tab only.
const TOKEN_KEY = "penumbra-token";
const fragmentToken = new URLSearchParams(location.hash.slice(1)).get("token");
if (fragmentToken) {
  sessionStorage.setItem(TOKEN_KEY, fragmentToken);
  window.history.replaceState(null, "", location.pathname);
}

function authHeaders() {
  const token = sessionStorage.getItem(TOKEN_KEY);
  return token ? { authorization: `Bearer ${token}` } : {};
}

// Asks for a token after a 401 (once; a wrong one asks again on the next 401).
function askForToken() {
  if (document.getElementById("token-form")) return;
  const form = document.createElement("form");
  form.id = "token-form";
  form.innerHTML = '<input type="password" placeholder="bearer token" autocomplete="off"> <button>use</button>';
  form.onsubmit = (event) => {
    event.preventDefault();
    sessionStorage.setItem(TOKEN_KEY, form.querySelector("input").value.trim());
    form.remove();
    poll();
  };
  document.querySelector("header").append(form);
}

function chart(id, config) {
  return new Chart(document.getElementById(id), config);
}

const loadChart = chart("chart-load", {
  type: "line",
  data: {
    labels: history.labels,
    datasets: [
      { label: "jobs / min", data: history.throughput, borderColor: "#f0b429", yAxisID: "y", pointRadius: 0, tension: 0.2 },
      { label: "backlog", data: history.queued, borderColor: "#58a6ff", yAxisID: "q", pointRadius: 0, stepped: true },
      { label: "rendering", data: history.running, borderColor: "#3fb950", yAxisID: "q", pointRadius: 0, stepped: true },
    ],
  },
  options: {
    scales: {
      y: { beginAtZero: true, title: { display: true, text: "jobs / min" } },
      q: { beginAtZero: true, position: "right", grid: { drawOnChartArea: false }, ticks: { precision: 0 }, title: { display: true, text: "jobs" } },
    },
  },
});

const latencyChart = chart("chart-latency", {
  type: "bar",
  data: {
    labels: [],
    datasets: [
      { label: "p50", data: [], backgroundColor: "#3fb950" },
      { label: "p95", data: [], backgroundColor: "#f0b429" },
      { label: "max", data: [], backgroundColor: "#ff7b72" },
    ],
  },
  options: { scales: { y: { type: "logarithmic", title: { display: true, text: "ms" } } } },
});

const phaseChart = chart("chart-phases", {
  type: "bar",
  data: { labels: [], datasets: [] },
  options: {
    scales: { x: { stacked: true, ticks: { maxRotation: 60, autoSkip: true } }, y: { stacked: true, title: { display: true, text: "ms" } } },
    plugins: { tooltip: { mode: "index" } },
  },
});

const cacheChart = chart("chart-cache", {
  type: "doughnut",
  data: { labels: ["used", "free"], datasets: [{ data: [0, 1], backgroundColor: ["#f0b429", "#2a313b"], borderWidth: 0 }] },
  options: { plugins: { legend: { position: "right" } } },
});

function bytes(n) {
  const units = ["B", "KiB", "MiB", "GiB", "TiB"];
  let i = 0;
  while (n >= 1024 && i < units.length - 1) {
    n /= 1024;
    i += 1;
  }
  return `${n.toFixed(n < 10 && i > 0 ? 1 : 0)} ${units[i]}`;
}

function duration(seconds) {
  const h = Math.floor(seconds / 3600);
  const m = Math.floor((seconds % 3600) / 60);
  return h > 0 ? `up ${h} h ${m} min` : `up ${m} min ${Math.floor(seconds % 60)} s`;
}

function setText(id, text) {
  document.getElementById(id).textContent = text;
}

function ratio(reused, created) {
  const all = reused + created;
  return all === 0 ? "–" : `${Math.round((100 * reused) / all)} %`;
}

// Sums a count over the live replicas.
function total(stats, key) {
  return stats.cluster.replicas.reduce((sum, r) => sum + r[key], 0);
}

function drawTiles(stats) {
  const uploads = stats.engine.uploads;
  setText("replica", `answered by ${stats.replica}`);
  setText("adapter", `${stats.adapter.name} (${stats.adapter.backend})`);
  setText("uptime", duration(stats.uptime_s));
  setText("throughput", stats.jobs.per_minute.toFixed(1));
  const backlog = stats.backlog;
  setText("backlog", backlog ? String(backlog.jobs) : "unknown");
  const oldest = backlog && backlog.oldest_age_seconds !== null ? `oldest ${backlog.oldest_age_seconds.toFixed(0)} s` : "none waiting";
  setText("backlog-unit", backlog ? `jobs waiting in the service · ${oldest}` : "the store cannot be read");
  const scope = stats.cluster.scope === "cluster" ? "" : " (this replica only)";
  setText("replicas", String(stats.cluster.replicas.length));
  setText("replicas-unit", `${total(stats, "jobs_in_flight")} rendering · ${total(stats, "jobs_queued")} waiting${scope}`);
  setText("cache", bytes(uploads.bytes));
  setText("cache-unit", `of ${bytes(uploads.budget_bytes)} · ${uploads.entries} assets`);
  const e = stats.engine;
  setText("pools", ratio(e.targets_reused + e.readbacks_reused + e.derived_reused, e.targets_created + e.readbacks_created + e.derived_created));
  setText("resets", String(e.device_resets));
  drawStore(stats.store, stats.connections);
}

// The job store's state: red while it does not answer or its disk is at the margin, with
// the free space, the results waiting for it and the connections held.
function drawStore(store, connections) {
  const tile = document.getElementById("store-tile");
  const held = connections ? ` · ${connections.open} connections` : "";
  if (!store) {
    setText("store", "memory");
    setText("store-unit", `not durable${held}`);
    tile.classList.remove("alarm");
    return;
  }
  const state = !store.available ? "unavailable" : !store.room ? "disk full" : "ok";
  setText("store", state);
  const free = store.free_bytes === undefined ? store.kind : `${store.kind} · ${bytes(store.free_bytes)} free`;
  const waiting = store.waiting_writes > 0 ? ` · ${store.waiting_writes} results waiting` : "";
  setText("store-unit", `${free}${waiting}${held}`);
  tile.classList.toggle("alarm", state !== "ok");
}

function drawHistory(stats) {
  history.labels.push(new Date().toLocaleTimeString());
  history.throughput.push(stats.jobs.per_minute);
  history.queued.push(stats.backlog ? stats.backlog.jobs : null);
  history.running.push(total(stats, "jobs_in_flight"));
  if (history.labels.length > HISTORY_POINTS) {
    for (const series of Object.values(history)) series.shift();
  }
  loadChart.update();
}

function drawLatency(stats) {
  const methods = Object.keys(stats.jobs.by_method);
  latencyChart.data.labels = methods;
  const pick = (key) => methods.map((m) => Math.max(stats.jobs.by_method[m][key], 0.01));
  latencyChart.data.datasets[0].data = pick("p50_ms");
  latencyChart.data.datasets[1].data = pick("p95_ms");
  latencyChart.data.datasets[2].data = pick("max_ms");
  latencyChart.update();
}

// One stacked bar per recent successful job (oldest left), one colour per render phase.
function drawPhases(stats) {
  const jobs = stats.jobs.recent.filter((j) => j.outcome === "ok").reverse();
  const phases = [];
  for (const job of jobs) for (const [name] of job.phases) if (!phases.includes(name)) phases.push(name);
  phaseChart.data.labels = jobs.map((j) => `${j.method} ${j.width}×${j.height}`);
  phaseChart.data.datasets = phases.map((phase, k) => ({
    label: phase,
    backgroundColor: PHASE_COLOURS[k % PHASE_COLOURS.length],
    data: jobs.map((j) => (j.phases.find(([name]) => name === phase) || [phase, 0])[1]),
  }));
  phaseChart.update();
  document.body.dataset.phaseBars = String(jobs.length);
  document.body.dataset.phases = phases.join(",");
}

function drawCache(stats) {
  const u = stats.engine.uploads;
  cacheChart.data.labels = [`used ${bytes(u.bytes)}`, `free ${bytes(Math.max(u.budget_bytes - u.bytes, 0))}`];
  cacheChart.data.datasets[0].data = [u.bytes, Math.max(u.budget_bytes - u.bytes, 0)];
  cacheChart.update();
}

// Replaces a table's rows: one per item, each cell's text from `cells(item)`.
function fillTable(id, items, cells, decorate) {
  const body = document.querySelector(`#${id} tbody`);
  body.replaceChildren(
    ...items.map((item) => {
      const row = document.createElement("tr");
      for (const text of cells(item)) {
        const cell = document.createElement("td");
        cell.textContent = text;
        row.append(cell);
      }
      decorate(row, item);
      return row;
    }),
  );
}

// A row per live replica (the one that answered marked), and the counts summed over them.
function drawReplicas(stats) {
  const now = Date.now();
  fillTable(
    "replica-table",
    stats.cluster.replicas,
    (r) => [r.replica, r.adapter, r.jobs_in_flight, r.jobs_queued, r.jobs_succeeded, r.jobs_failed, duration((now - r.started_unix_ms) / 1000).slice(3), `${Math.max(0, (now - r.heartbeat_unix_ms) / 1000).toFixed(0)} s ago`],
    (row, r) => {
      row.dataset.replica = r.replica;
      row.classList.toggle("self", r.replica === stats.replica);
    },
  );
  document.body.dataset.replicas = String(stats.cluster.replicas.length);
  document.body.dataset.replicaNames = stats.cluster.replicas.map((r) => r.replica).join(",");
  document.body.dataset.jobsSucceeded = String(total(stats, "jobs_succeeded"));
  document.body.dataset.answeredBy = stats.replica;
}

// The newest finished jobs of the service, each naming the replica that rendered it.
function drawJobs(stats) {
  fillTable(
    "job-table",
    stats.jobs.recent,
    (j) => [new Date(j.finished_unix_ms).toLocaleTimeString(), j.method, `${j.width}×${j.height}`, j.replica, j.outcome, j.wall_ms.toFixed(0)],
    (row, j) => {
      row.dataset.replica = j.replica;
      row.children[4].classList.toggle("failed", j.outcome !== "ok");
    },
  );
}

// Removes a grid's figures whose job is no longer wanted, letting their images' blobs go.
function removeStale(box, wanted) {
  for (const child of [...box.children]) {
    if (!wanted.has(child.dataset.id)) {
      const img = child.querySelector("img");
      if (img && img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
      child.remove();
    }
  }
}

// Thumbnails of the newest successful jobs; ids are unique, so existing images are kept.
function drawThumbnails(stats) {
  const box = document.getElementById("thumbnails");
  const jobs = stats.jobs.recent.filter((j) => j.outcome === "ok").slice(0, 12);
  const wanted = new Set(jobs.map((j) => j.id));
  removeStale(box, wanted);
  jobs.forEach((job, k) => {
    let item = box.querySelector(`[data-id="${job.id}"]`);
    if (!item) {
      item = document.createElement("figure");
      item.dataset.id = job.id;
      const img = document.createElement("img");
      img.alt = `${job.method} render`;
      img.dataset.src = `/v1/jobs/${encodeURIComponent(job.id)}/thumbnail`;
      // Fetched with the token (an <img src> could not send it); a thumbnail that expired
      // from the server's store leaves the grid.
      fetch(img.dataset.src, { headers: authHeaders() })
        .then((r) => (r.ok ? r.blob() : Promise.reject(new Error(String(r.status)))))
        .then((blob) => (img.src = URL.createObjectURL(blob)))
        .catch(() => item.remove());
      const caption = document.createElement("figcaption");
      caption.textContent = `${job.method} · ${job.wall_ms.toFixed(0)} ms · ${job.replica}`;
      item.append(img, caption);
    }
    if (box.children[k] !== item) box.insertBefore(item, box.children[k] || null);
  });
}

// Running progressive jobs refining (contract §5): each one's latest round, its image and its
// estimated error, redrawn when a new round comes; a job that ends leaves (its last round is
// then among the recent renders).
async function drawRefining() {
  const box = document.getElementById("refining");
  const response = await fetch("/v1/jobs?status=running&limit=8", { headers: { accept: "application/json", ...authHeaders() } });
  if (!response.ok) return;
  const running = (await response.json()).jobs;
  const records = await Promise.all(
    running.map((job) =>
      fetch(`/v1/jobs/${encodeURIComponent(job.id)}`, { headers: authHeaders() })
        .then((r) => (r.ok ? r.json() : null))
        .catch(() => null),
    ),
  );
  const refining = records.filter((r) => r && r.round);
  const wanted = new Set(refining.map((r) => r.id));
  removeStale(box, wanted);
  for (const record of refining) {
    let item = box.querySelector(`[data-id="${record.id}"]`);
    if (!item) {
      item = document.createElement("figure");
      item.dataset.id = record.id;
      item.append(document.createElement("img"), document.createElement("figcaption"));
      box.append(item);
    }
    const round = record.round;
    if (item.dataset.round === String(round.round)) continue;
    item.dataset.round = String(round.round);
    const img = item.querySelector("img");
    img.alt = `round ${round.round} of a progressive job`;
    fetch(round.image, { headers: authHeaders() })
      .then((r) => (r.ok ? r.blob() : Promise.reject(new Error(String(r.status)))))
      .then((blob) => {
        if (img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
        img.src = URL.createObjectURL(blob);
      })
      .catch(() => {}); // moved past already: the next poll shows the next round
    const error = `${round.predicted ? "predicted" : "estimated"} error ${round.error_estimate.toFixed(4)}`;
    item.querySelector("figcaption").textContent = `round ${round.round} · ${round.method} · ${error} · ${(round.elapsed_ms / 1000).toFixed(1)} s`;
  }
  document.getElementById("refining-section").hidden = refining.length === 0;
  document.body.dataset.refining = refining.map((r) => `${r.id}:${r.round.round}`).join(",");
}

async function poll() {
  const status = document.getElementById("status");
  try {
    const response = await fetch("/v1/stats", { headers: { accept: "application/json", ...authHeaders() } });
    if (response.status === 401) askForToken();
    if (!response.ok) throw new Error(`HTTP ${response.status}`);
    const stats = await response.json();
    drawTiles(stats);
    drawHistory(stats);
    drawLatency(stats);
    drawPhases(stats);
    drawCache(stats);
    drawReplicas(stats);
    drawJobs(stats);
    drawThumbnails(stats);
    await drawRefining();
    status.textContent = "live";
    status.className = "status ok";
    polls += 1;
    document.body.dataset.polls = String(polls);
    document.body.dataset.recentJobs = String(stats.jobs.recent.length);
  } catch (error) {
    status.textContent = `unreachable (${error.message})`;
    status.className = "status down";
  }
}

poll();
setInterval(poll, POLL_MS);
