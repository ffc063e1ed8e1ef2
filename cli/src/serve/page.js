// The page of `unshear serve`: each photo dropped or chosen is sent to /api/estimate (with its
// annotated picture), shown with its shear, compared before and after through /api/correct
// (a JPEG preview), and downloaded corrected in its own format. No library, no build step.
"use strict";

const $ = (selector, root = document) => root.querySelector(selector);
const drop = $("#drop");
const input = $("#files");
const results = $("#results");
const status = $("#status");
const cards = [];
let maxUpload = 64 << 20;
let queue = Promise.resolve();
let pending = 0;

// Formats a browser shows by itself; others (TIFF, PNM) get their "before" from the server.
const SHOWN = ["image/jpeg", "image/png", "image/webp", "image/bmp", "image/gif"];

const fmt = (k) => (k >= 0 ? "+" : "") + k.toFixed(3);

function megabytes(n) {
  return (n / (1 << 20)).toFixed(n < 10 << 20 ? 1 : 0) + " MB";
}

fetch("/api/health")
  .then((r) => r.json())
  .then((h) => {
    maxUpload = h.max_upload;
    $("#limit").textContent = megabytes(maxUpload);
  })
  .catch(() => {});

function setStatus() {
  status.textContent = pending > 0 ? `Working on ${pending} photo${pending > 1 ? "s" : ""}…` : "";
  document.body.dataset.state = pending > 0 ? "working" : "idle";
}

// The error of a failed request in words, from the API's {"error": {"code", "message"}}.
async function failure(response) {
  let code = "";
  let message = `${response.status} ${response.statusText}`;
  try {
    const body = await response.json();
    code = body.error.code;
    message = body.error.message;
  } catch (e) {
    // Not JSON: keep the status line.
  }
  const lead = {
    unreadable: "This file could not be read as an image.",
    empty: "This file is empty.",
    upload_too_large: "This file is too large.",
    too_many_pixels: "This image has too many pixels.",
    unsupported_media_type: "This file type is not accepted.",
    no_face: "No usable face was found.",
    busy: "The server is busy; try again in a moment.",
  }[code];
  return lead ? `${lead} (${message})` : message;
}

function addFiles(files) {
  for (const file of files) {
    const card = makeCard(file);
    cards.push(card);
    results.append(card.root);
    $("#bar").hidden = false;
    document.body.classList.add("has-results");
    pending += 1;
    setStatus();
    // One photo at a time from this page: the server has its own limit for all clients.
    queue = queue.then(() => estimate(card)).finally(() => {
      pending -= 1;
      setStatus();
    });
  }
}

function makeCard(file) {
  const root = $("#card").content.firstElementChild.cloneNode(true);
  const card = {
    file,
    root,
    report: null,
    k: null,
    preview: null,
    urls: [],
    el: (s) => $(s, root),
  };
  card.el(".name").textContent = file.name;
  card.el(".k").textContent = "…";
  return card;
}

function showError(card, message) {
  const e = card.el(".error");
  e.textContent = message;
  e.hidden = false;
  card.el(".k").textContent = "";
  card.root.classList.add("failed");
}

function url(card, blob) {
  const u = URL.createObjectURL(blob);
  card.urls.push(u);
  return u;
}

function query(params) {
  return new URLSearchParams(params).toString();
}

async function estimate(card) {
  const file = card.file;
  if (file.size > maxUpload) {
    showError(card, `This file is too large: ${megabytes(file.size)}, the server takes up to ${megabytes(maxUpload)}.`);
    return;
  }
  if (file.size === 0) {
    showError(card, "This file is empty.");
    return;
  }
  let response;
  try {
    response = await fetch("/api/estimate?" + query({ annotate: "true", name: file.name }), {
      method: "POST",
      headers: { "Content-Type": file.type || "application/octet-stream" },
      body: file,
    });
  } catch (e) {
    showError(card, `The server could not be reached (${e.message}).`);
    return;
  }
  if (!response.ok) {
    showError(card, await failure(response));
    return;
  }
  const report = await response.json();
  card.report = report;
  showReport(card, report);
}

function showReport(card, report) {
  const k = card.el(".k");
  if (report.k !== null) {
    const best = Math.max(...report.faces.map((f) => f.confidence));
    k.textContent = `k = ${fmt(report.k)}`;
    k.dataset.k = fmt(report.k);
    const n = report.faces.length;
    card.el(".description").textContent =
      `confidence ${best.toFixed(2)}, ${n} face${n === 1 ? "" : "s"} found`;
    // The CLI's own sentence (the scene's verticals, faces that disagree, ...).
    card.el(".detail").textContent = report.description;
  } else {
    k.textContent = "No usable face";
    card.el(".description").textContent =
      `${report.description}. Set k by hand to correct anyway.`;
    card.root.classList.add("refused");
  }
  if (report.warnings.length > 0) {
    const w = card.el(".warning");
    w.textContent = report.warnings.join(" ");
    w.hidden = false;
  }
  card.el(".annotated img").src = report.annotated;
  card.el(".views").hidden = false;
  card.el(".controls").hidden = false;
  const before = card.el(".before");
  if (SHOWN.includes(card.file.type)) {
    before.src = url(card, card.file);
  } else {
    correctedBlob(card, 0, "jpeg").then(({ blob }) => (before.src = url(card, blob)), () => {});
  }
  wire(card);
  if (report.k === null) {
    // Nothing to correct until k is set by hand.
    setK(card, 0, false);
    card.k = null;
    card.el(".download").disabled = true;
  } else {
    setK(card, report.k);
  }
}

function setK(card, k, preview = true) {
  card.k = k;
  card.el(".k-range").value = String(k);
  card.el(".k-number").value = k.toFixed(3);
  card.el(".download").disabled = false;
  if (preview) schedulePreview(card);
}

function wire(card) {
  const range = card.el(".k-range");
  const number = card.el(".k-number");
  range.addEventListener("input", () => {
    card.k = Number(range.value);
    number.value = card.k.toFixed(3);
    card.el(".download").disabled = false;
    schedulePreview(card);
  });
  number.addEventListener("change", () => {
    const k = Number(number.value);
    if (Number.isFinite(k) && Math.abs(k) <= 10) setK(card, k);
  });
  card.el(".reset").addEventListener("click", () => {
    if (card.report.k !== null) setK(card, card.report.k);
  });
  card.el(".reset").disabled = card.report.k === null;
  card.el(".canvas").addEventListener("change", () => schedulePreview(card));
  const split = card.el(".split");
  const after = card.el(".after");
  const clip = () => (after.style.clipPath = `inset(0 0 0 ${split.value}%)`);
  split.addEventListener("input", clip);
  clip();
  const toggle = card.el(".toggle");
  toggle.addEventListener("click", () => {
    const showBefore = toggle.getAttribute("aria-pressed") !== "true";
    toggle.setAttribute("aria-pressed", String(showBefore));
    toggle.textContent = showBefore ? "Show after" : "Show before";
    after.hidden = showBefore;
  });
  card.el(".download").addEventListener("click", () => download(card));
}

async function correctedBlob(card, k, format) {
  const params = { k: String(k), canvas: card.el(".canvas").value, name: card.file.name };
  if (format) params.format = format;
  const response = await fetch("/api/correct?" + query(params), {
    method: "POST",
    headers: { "Content-Type": card.file.type || "application/octet-stream" },
    body: card.file,
  });
  if (!response.ok) throw new Error(await failure(response));
  return { blob: await response.blob(), response };
}

function schedulePreview(card) {
  clearTimeout(card.preview);
  card.preview = setTimeout(async () => {
    const k = card.k;
    const after = card.el(".after");
    after.classList.add("stale");
    try {
      const { blob } = await correctedBlob(card, k, "jpeg");
      if (card.k === k) after.src = url(card, blob);
    } catch (e) {
      showError(card, e.message);
    } finally {
      after.classList.remove("stale");
    }
  }, 250);
}

async function download(card) {
  if (card.k === null) return;
  const button = card.el(".download");
  button.disabled = true;
  try {
    const { blob, response } = await correctedBlob(card, card.k, null);
    const disposition = response.headers.get("Content-Disposition") || "";
    const match = /filename="([^"]+)"/.exec(disposition);
    const a = document.createElement("a");
    a.href = url(card, blob);
    a.download = match ? match[1] : "corrected";
    document.body.append(a);
    a.click();
    a.remove();
  } catch (e) {
    showError(card, e.message);
  } finally {
    button.disabled = false;
  }
}

drop.addEventListener("click", () => input.click());
drop.addEventListener("keydown", (e) => {
  if (e.key === "Enter" || e.key === " ") {
    e.preventDefault();
    input.click();
  }
});
input.addEventListener("change", () => {
  addFiles([...input.files]);
  input.value = "";
});
for (const type of ["dragenter", "dragover"]) {
  drop.addEventListener(type, (e) => {
    e.preventDefault();
    drop.classList.add("over");
  });
}
for (const type of ["dragleave", "drop"]) {
  drop.addEventListener(type, () => drop.classList.remove("over"));
}
drop.addEventListener("drop", (e) => {
  e.preventDefault();
  addFiles([...e.dataTransfer.files]);
});
// Dropping a photo anywhere else must not navigate away from the page.
window.addEventListener("dragover", (e) => e.preventDefault());
window.addEventListener("drop", (e) => e.preventDefault());

$("#download-all").addEventListener("click", async () => {
  for (const card of cards) {
    if (card.report && card.k !== null) await download(card);
  }
});
$("#clear").addEventListener("click", () => {
  for (const card of cards) card.urls.forEach((u) => URL.revokeObjectURL(u));
  cards.length = 0;
  results.textContent = "";
  $("#bar").hidden = true;
  document.body.classList.remove("has-results");
});

// `?demo=example`: put the bundled example photo through the page; `?demo=bad`: a photo
// without a face and a text file named as a photo (the browser test uses both).
const demo = new URLSearchParams(location.search).get("demo");
if (demo === "bad") {
  const canvas = document.createElement("canvas");
  canvas.width = 160;
  canvas.height = 120;
  const g = canvas.getContext("2d");
  g.fillStyle = "#888";
  g.fillRect(0, 0, canvas.width, canvas.height);
  canvas.toBlob((blob) => {
    addFiles([
      new File([blob], "blank.png", { type: "image/png" }),
      new File(["not a photo\n"], "notes.jpg", { type: "image/jpeg" }),
    ]);
  }, "image/png");
}
if (demo === "example") {
  pending += 1;
  setStatus();
  fetch("/example.png")
    .then((r) => r.blob())
    .then((blob) => {
      pending -= 1;
      addFiles([new File([blob], "face-k0.30.png", { type: "image/png" })]);
    });
}
setStatus();
