#!/usr/bin/env node
"use strict";
/**
 * A vendor-style PLC that runs the four-tank process, served over OPC UA by node-opcua (a
 * second OPC UA stack, beside asyncua): the live tests' plant that was not written by the
 * project's own server.
 *
 *   node server.js --config case.json [--port N] [--speed K] [--record FILE] [--duration S]
 *
 * It looks like a vendor's PLC: its own namespace URI (not at index 2), tags named after the
 * plant's instruments with string ids (ns=<i>;s=PLC1.LT101.PV) and numeric ids
 * (ns=<i>;i=1002), AnalogItems with EngineeringUnits (UNECE codes) and EURange, levels in m,
 * mm or % of span, pump outputs in m3/s or %, Float, Double or Int16. It IS the plant: the
 * four tanks (plant.js) stepped on the wall clock, one sample of Ts every Ts / K seconds, the
 * inputs as last written (zero-order hold). config.js describes the case file: a clock
 * offset, read-time stamps, a frozen value, a value with status Good that no level can have,
 * a deleted node.
 *
 * It binds 127.0.0.1 only, prints one line when it listens ("vendor-plc listening {json}"),
 * stops on SIGTERM or SIGINT and by itself after `duration` seconds (exit 0); a bad case is
 * one line on stderr, exit 2. Its record (CSV, flushed per row) is what reached the plant:
 * one "sample" row per step (time, the raw values published and received, the process in SI
 * units), one "write" row per value written by a client, with its wall-clock time, and one
 * "heartbeat" row per write of the APC heartbeat node (PLC1/APC/WD, Int32).
 */

const fs = require("fs");
const os = require("os");
const path = require("path");
const { OPCUAServer } = require("node-opcua-server");
const { OPCUACertificateManager } = require("node-opcua-certificate-manager");
const { DataType, Variant } = require("node-opcua-variant");
const { DataValue } = require("node-opcua-data-value");
const { StatusCodes } = require("node-opcua-status-code");
const { makeEUInformation } = require("node-opcua-data-access");
const { nodesets } = require("node-opcua-nodesets");
const { MessageSecurityMode } = require("node-opcua-types");
const { SecurityPolicy } = require("node-opcua-secure-channel");
const plant = require("./plant.js");
const config = require("./config.js");

const SIGNALS = ["h1", "h2", "h3", "h4", "qa", "qb"];

/** The CSV record: a header, then rows written at once (a killed PLC keeps its rows). */
class Record {
  constructor(file) {
    this.fd = file ? fs.openSync(file, "w") : null;
    this.columns = ["event", "wall_time", "sample", "time", "source_time", "node", "type",
                    ...SIGNALS.map((s) => `raw.${s}`), ...SIGNALS, "heartbeat"];
    this.write(this.columns);
  }

  write(fields) {
    if (this.fd !== null) {
      fs.writeSync(this.fd, fields.map((v) => (v === null || v === undefined ? "" : String(v)))
        .join(",") + "\n");
    }
  }

  row(values) {
    this.write(this.columns.map((c) => values[c]));
  }

  close() {
    if (this.fd !== null) fs.closeSync(this.fd);
    this.fd = null;
  }
}

/** The process, its tags and the faults of the case. */
class Plc {
  constructor(cfg) {
    this.cfg = cfg;
    this.tags = cfg.tags;
    this.h = plant.START.h.slice();
    this.n = 0;                      // samples stepped: the process is at time n Ts
    this.frozen = cfg.frozen;
    this.written = false;
    this.raw = {};                   // the raw value each tag holds
    this.values = {};                // the DataValue each tag serves
    this.nodes = {};
    this.published = 0;              // source time of the last publication [s]
    this.overruns = 0;
    this.record = new Record(cfg.record);
    for (const s of ["qa", "qb"]) this.raw[s] = config.toRaw(this.tags[s], plant.START[s]);
  }

  now() {
    return new Date(Date.now() + 1000 * this.cfg.clock_offset);
  }

  dataValue(tag, raw, when) {
    return new DataValue({
      value: new Variant({ dataType: DataType[tag.type], value: raw }),
      statusCode: StatusCodes.Good, sourceTimestamp: when, serverTimestamp: when,
    });
  }

  /** What a read of a tag returns: as published, or stamped now (stamp_reads). */
  served(signal) {
    const dv = this.values[signal];
    if (!this.cfg.stamp_reads) return dv;
    return this.dataValue(this.tags[signal], this.raw[signal], this.now());
  }

  /** A client's write: kept (the next sample applies it) and recorded. */
  async received(signal, dataValue) {
    const tag = this.tags[signal];
    const raw = Number(dataValue.value.value);
    this.raw[signal] = raw;
    this.values[signal] = this.dataValue(tag, raw, this.now());
    this.written = true;
    this.record.row({
      event: "write", wall_time: Date.now() / 1000, sample: this.n, time: this.n * this.cfg.Ts,
      node: this.nodes[signal].nodeId.toString(), type: DataType[dataValue.value.dataType],
      [`raw.${signal}`]: raw, [signal]: config.fromRaw(tag, raw),
    });
    return StatusCodes.Good;
  }

  /** The inputs in SI units, each within its span (a PLC clamps its outputs). */
  inputs() {
    const u = {};
    for (const s of ["qa", "qb"]) {
      const v = config.fromRaw(this.tags[s], this.raw[s]);
      const [lo, hi] = this.tags[s].span;
      u[s] = Number.isFinite(v) ? Math.min(Math.max(v, lo), hi) : lo;
    }
    return u;
  }

  /** One sample: thaw at the first write, record, step the process Ts, publish. */
  tick() {
    if (this.frozen && this.written) this.frozen = false;
    if (!this.frozen) {
      const u = this.inputs();
      const row = { event: "sample", wall_time: Date.now() / 1000, sample: this.n,
                    time: this.n * this.cfg.Ts, source_time: this.published, ...u };
      SIGNALS.forEach((s, i) => {
        row[`raw.${s}`] = this.raw[s];
        if (i < 4) row[s] = this.h[i];
      });
      this.record.row(row);
      this.h = plant.step(this.h, u.qa, u.qb, this.cfg.Ts);
      this.n += 1;
    }
    this.applyDeletes();
    this.publish();
  }

  /** The levels of sample n, stamped now, but for the case's frozen and bad values. */
  publish() {
    const when = this.now();
    this.published = when.getTime() / 1000;
    SIGNALS.slice(0, 4).forEach((s, i) => {
      const tag = this.tags[s];
      if (this.values[s] !== undefined && this.fault("freeze", s)) return;
      const bad = this.fault("value", s);
      this.raw[s] = config.cast(tag, bad ? bad.value : config.toRaw(tag, this.h[i]));
      this.values[s] = this.dataValue(tag, this.raw[s], when);
    });
  }

  /** The case's fault of this kind on the signal that acts at sample n, if any. */
  fault(kind, signal) {
    const n = this.n;
    return this.cfg.faults.find((f) => f.kind === kind && f.tag === signal &&
      (kind === "freeze" ? n >= f.from : n >= f.from && n < f.to));
  }

  applyDeletes() {
    for (const f of this.cfg.faults) {
      if (f.kind === "delete" && this.n >= f.at && !f.done) {
        f.done = true;
        this.addressSpace.deleteNode(this.nodes[f.tag].nodeId);
        delete this.nodes[f.tag];
      }
    }
  }

  /** The address space: Objects/PLC1/{Levels, Pumps}/<tag> AnalogItems. */
  build(server) {
    const addressSpace = server.engine.addressSpace;
    this.addressSpace = addressSpace;
    for (let i = 0; i < this.cfg.namespaces_before; i++) {
      addressSpace.registerNamespace(`${this.cfg.namespace}:diagnostics${i || ""}`);
    }
    const ns = addressSpace.registerNamespace(this.cfg.namespace);
    this.index = ns.index;
    const plc = ns.addFolder(addressSpace.rootFolder.objects,
                             { nodeId: "s=PLC1", browseName: "PLC1" });
    const folders = {};
    for (const name of ["Levels", "Pumps", "APC"]) {
      folders[name] = ns.addFolder(plc, { nodeId: `s=PLC1.${name}`, browseName: name });
    }
    this.publish();
    for (const s of SIGNALS) this.nodes[s] = this.analogItem(ns, folders, this.tags[s]);
    this.watchdogNode(ns, folders.APC);
  }

  /** APC/WD (ns=<i>;s=PLC1.APC.WD, Int32, writable): the heartbeat an APC application
   * writes every sample; each write recorded ("heartbeat" rows). */
  watchdogNode(ns, folder) {
    let value = new DataValue({ value: new Variant({ dataType: DataType.Int32, value: 0 }),
                                sourceTimestamp: this.now() });
    ns.addVariable({
      componentOf: folder, nodeId: "s=PLC1.APC.WD", browseName: "WD", dataType: "Int32",
      accessLevel: "CurrentRead | CurrentWrite", userAccessLevel: "CurrentRead | CurrentWrite",
      value: {
        timestamped_get: () => value,
        timestamped_set: async (dv) => {
          value = new DataValue({ value: dv.value, sourceTimestamp: this.now() });
          this.record.row({ event: "heartbeat", wall_time: Date.now() / 1000, sample: this.n,
                            time: this.n * this.cfg.Ts, node: "s=PLC1.APC.WD",
                            type: DataType[dv.value.dataType], heartbeat: dv.value.value });
          return StatusCodes.Good;
        },
      },
    });
  }

  analogItem(ns, folders, tag) {
    const unit = config.UNITS[tag.unit];
    const [low, high] = config.rangeOf(tag);
    const writable = tag.role === "input";
    const access = writable ? "CurrentRead | CurrentWrite" : "CurrentRead";
    if (writable) this.values[tag.signal] = this.dataValue(tag, this.raw[tag.signal], this.now());
    const value = { timestamped_get: () => this.served(tag.signal) };
    if (writable) value.timestamped_set = (dv) => this.received(tag.signal, dv);
    return ns.addAnalogDataItem({
      organizedBy: folders[tag.folder], nodeId: tag.id, browseName: tag.name,
      description: tag.description, dataType: tag.type, accessLevel: access,
      userAccessLevel: access, minimumSamplingInterval: 50,
      engineeringUnitsRange: { low, high },
      engineeringUnits: makeEUInformation(unit.code, unit.display, unit.text), value,
    });
  }
}

async function start(cfg) {
  const pki = fs.mkdtempSync(path.join(os.tmpdir(), "vendor-plc-pki-"));
  process.on("exit", () => fs.rmSync(pki, { recursive: true, force: true }));
  const manager = new OPCUACertificateManager({
    rootFolder: pki, automaticallyAcceptUnknownCertificate: true,
  });
  const server = new OPCUAServer({
    port: cfg.port, host: "127.0.0.1", hostname: "127.0.0.1",
    nodeset_filename: [nodesets.standard],
    serverCertificateManager: manager,
    securityPolicies: [SecurityPolicy.None], securityModes: [MessageSecurityMode.None],
    allowAnonymous: true,
    buildInfo: { productName: "ACME PLC1 (vendor-style four tanks)", manufacturerName: "ACME" },
  });
  await server.initialize();
  const plc = new Plc(cfg);
  plc.build(server);
  await server.start();
  return { server, plc };
}

/** Step the PLC every Ts / K seconds of the wall clock, drift-free, until stopped. */
function run(plc, periodMs) {
  const t0 = performance.now();
  let k = 0;
  let timer = null;
  const next = () => {
    k += 1;
    let delay = t0 + k * periodMs - performance.now();
    if (delay < -periodMs) {            // fell more than a sample behind: resynchronise
      plc.overruns += 1;
      k = Math.ceil((performance.now() - t0) / periodMs);
      delay = t0 + k * periodMs - performance.now();
    }
    timer = setTimeout(() => {
      plc.tick();
      next();
    }, Math.max(delay, 0));
  };
  next();
  return () => clearTimeout(timer);
}

async function main() {
  let cfg;
  try {
    cfg = config.load(process.argv.slice(2));
  } catch (err) {
    if (!(err instanceof config.ConfigError)) throw err;
    process.stderr.write(`vendor-plc: ${err.message}\n`);
    process.exit(2);
  }
  const { server, plc } = await start(cfg);
  const periodMs = (1000 * cfg.Ts) / cfg.speed;
  const stopTicks = run(plc, periodMs);
  let stopping = false;
  const stop = (why) => {
    if (stopping) return;
    stopping = true;
    stopTicks();
    plc.record.close();
    setTimeout(() => process.exit(0), 2000).unref();
    server.shutdown(0).finally(() => {
      process.stderr.write(`vendor-plc: stopped (${why}) after ${plc.n} samples, ` +
                           `${plc.overruns} overruns\n`);
      process.exit(0);
    });
  };
  process.on("SIGTERM", () => stop("SIGTERM"));
  process.on("SIGINT", () => stop("SIGINT"));
  setTimeout(() => stop("duration"), 1000 * cfg.duration).unref();
  process.stdout.write(`vendor-plc listening ${JSON.stringify({
    endpoint: `opc.tcp://127.0.0.1:${cfg.port}`, namespace: cfg.namespace,
    namespace_index: plc.index, period_s: periodMs / 1000, pid: process.pid,
  })}\n`);
}

main().catch((err) => {
  process.stderr.write(`vendor-plc: ${err && err.message ? err.message : err}\n`);
  process.exit(1);
});
