// tactile firmware emulator: runs the RP2040 firmware ELF in rp2040js, in lock step with a
// plant that lives in another process (hil-sim).
//
//   node emulator/src/main.js --elf FIRMWARE.elf [--unique-id HEX16] [--seed N] [--verbose]
//
// Protocol: one JSON object per line on stdin, one reply per line on stdout. The first line
// written is {"ready": ...}. Simulated time is the emulator's clock (ns since power-on); the
// caller advances it explicitly, so nothing here depends on the wall clock.
//
//   {"op":"run","until_ns":N,"proximity_v":V,"manometer_v":V,"load_counts":C,
//    "adc_noise_lsb":L,"hx711_period_ns":P,"rx":"HEX"}
//     -> {"t_ns":N,"pump":D,"led":D,"vent_open":B,"steps":S,"stepper_enabled":B,"tx":"HEX",
//         "resets":[{"t_ns":N,"reason":"timeout"|"trigger"}]}
//   {"op":"hang"}    the CPU stops executing (a firmware hang; timers keep counting)
//   {"op":"report"}  -> counters, USB state, longest control tick, PWM periods
//
// rx: bytes the host wrote to the serial port (CDC OUT); tx: bytes the device sent (CDC IN).

import fs from 'node:fs';
import path from 'node:path';
import readline from 'node:readline';
import { fileURLToPath } from 'node:url';

import { Board, Rng } from './board.js';
import { createChip } from './chip.js';
import { loadElfIntoFlash } from './elf.js';
import { UsbHost } from './usb-host.js';

const FLASH_SIZE = 16 * 1024 * 1024;
const NS_PER_CYCLE = 8; // 125 MHz clk_sys (embassy-rp's default clock setup)
const WATCHDOG_REASON_TIMER = 1;
// Watchdog SCRATCH4 value by which the boot ROM recognises a reboot to a vector it was
// given (its reset_usb_boot uses it to reboot into the USB bootloader).
const ROM_REBOOT_MAGIC = 0xb007c0d3;

function parseArgs(argv) {
  const args = { elf: null, uniqueId: 'E6614C311B7A8F2D', seed: 1, verbose: false, bootrom: null };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    if (a === '--elf') args.elf = argv[++i];
    else if (a === '--unique-id') args.uniqueId = argv[++i];
    else if (a === '--seed') args.seed = Number(argv[++i]);
    else if (a === '--bootrom') args.bootrom = argv[++i];
    else if (a === '--verbose') args.verbose = true;
    else throw new Error(`unknown argument ${a}`);
  }
  if (!args.elf) throw new Error('--elf FILE is required');
  if (!/^[0-9A-Fa-f]{16}$/.test(args.uniqueId ?? '')) {
    throw new Error('--unique-id needs 16 hex digits');
  }
  if (!Number.isSafeInteger(args.seed)) throw new Error('--seed needs an integer');
  return args;
}

function hexToBytes(hex) {
  if (typeof hex !== 'string' || hex.length % 2 !== 0 || !/^[0-9a-fA-F]*$/.test(hex)) {
    throw new Error('rx must be an even-length hex string');
  }
  return Uint8Array.from(Buffer.from(hex, 'hex'));
}

function finite(value, name) {
  if (typeof value !== 'number' || !Number.isFinite(value)) {
    throw new Error(`${name} must be a finite number`);
  }
  return value;
}

class Emulator {
  constructor(args) {
    const here = path.dirname(fileURLToPath(import.meta.url));
    const romPath = args.bootrom ?? path.join(here, '..', 'rom', 'bootrom-b1.bin');
    const rom = fs.readFileSync(romPath);
    if (rom.length !== 16384) throw new Error(`${romPath}: expected a 16 KiB boot ROM`);
    this.bootrom = new Uint32Array(rom.buffer, rom.byteOffset, 4096).slice();
    this.image = new Uint8Array(FLASH_SIZE).fill(0xff);
    loadElfIntoFlash(fs.readFileSync(args.elf), this.image);
    this.uniqueId = Array.from(Buffer.from(args.uniqueId, 'hex'));
    this.verbose = args.verbose;
    this.rng = new Rng(args.seed);
    this.inputs = {
      proximityV: 0,
      manometerV: 0,
      loadCounts: 0,
      adcNoiseLsb: 1.5,
      hx711PeriodNs: 12_500_000,
    };
    this.baseNs = 0; // simulated time at the current chip's power-on / reset
    this.hung = false;
    this.resets = [];
    this.pendingReset = null;
    this.tx = [];
    this.longestTickNs = 0;
    this.ticks = 0;
    this.boot({ resetReason: 0, scratch: null, runBootrom: false });
  }

  boot({ resetReason, scratch, runBootrom }) {
    const { rp, logger, watchdog } = createChip({
      bootrom: this.bootrom,
      image: this.image,
      uniqueId: this.uniqueId,
      resetReason,
      scratch,
      runBootrom,
      verbose: this.verbose,
    });
    this.rp = rp;
    this.logger = logger;
    this.watchdog = watchdog;
    watchdog.onWatchdogTrigger = () => {
      // The chip resets now: stop the expired timer (rp2040js's periodic alarm would fire
      // again at the same instant) and let the run loop build the rebooted chip.
      watchdog.timer.enable = false;
      watchdog.alarm.enable = false;
      this.pendingReset = { reason: watchdog.reason, scratch: watchdog.scratchData.slice() };
    };
    this.board = new Board(rp, watchdog, this.inputs, this.rng);
    this.usb = new UsbHost(rp, (data) => {
      for (const b of data) this.tx.push(b);
    });
  }

  get nowNs() {
    return this.baseNs + this.rp.clock.nanos;
  }

  resetChip() {
    const { reason, scratch } = this.pendingReset;
    this.pendingReset = null;
    this.collectTickStats();
    this.baseNs = this.nowNs;
    // The boot ROM runs after every reset. If the scratch registers carry its reboot magic
    // (left by reset_usb_boot), the emulated ROM runs and follows them (into BOOTSEL);
    // otherwise it would boot the flash, a path rp2040js cannot run (no XIP through the
    // SSI), so the chip enters boot2 directly as at power-on.
    const runBootrom = scratch[4] >>> 0 === ROM_REBOOT_MAGIC;
    this.resets.push({
      t_ns: this.baseNs,
      reason: reason === WATCHDOG_REASON_TIMER ? 'timeout' : 'trigger',
      rom_reboot: runBootrom,
      scratch: Array.from(scratch, (v) => v >>> 0),
    });
    this.hung = false;
    this.boot({ resetReason: reason, scratch, runBootrom });
  }

  collectTickStats() {
    this.longestTickNs = Math.max(this.longestTickNs, this.board.tick.longestNs);
    this.ticks += this.board.tick.count;
    this.board.tick.longestNs = 0;
    this.board.tick.count = 0;
  }

  run(untilNs) {
    for (;;) {
      if (this.pendingReset) this.resetChip();
      const rp = this.rp;
      const core = rp.core;
      const clock = rp.clock;
      const target = untilNs - this.baseNs;
      while (clock.nanos < target && !this.pendingReset) {
        if (this.hung || core.waiting) {
          // Nothing executes until the next alarm (an interrupt, or the watchdog).
          const next = clock.nextAlarm ? clock.nextAlarm.nanos : target;
          clock.tick(Math.max(0, Math.min(next, target) - clock.nanos));
        } else {
          clock.tick(core.executeInstruction() * NS_PER_CYCLE);
        }
      }
      if (!this.pendingReset) return;
    }
  }

  handle(msg) {
    switch (msg.op) {
      case 'run': {
        const until = finite(msg.until_ns, 'until_ns');
        this.inputs.proximityV = finite(msg.proximity_v, 'proximity_v');
        this.inputs.manometerV = finite(msg.manometer_v, 'manometer_v');
        this.inputs.loadCounts = finite(msg.load_counts, 'load_counts');
        this.inputs.adcNoiseLsb = finite(msg.adc_noise_lsb, 'adc_noise_lsb');
        this.inputs.hx711PeriodNs = Math.max(1e5, finite(msg.hx711_period_ns, 'hx711_period_ns'));
        if (msg.rx) this.usb.write(hexToBytes(msg.rx));
        const resetsBefore = this.resets.length;
        this.run(until);
        const out = this.board.takeOutputs();
        const tx = Buffer.from(this.tx).toString('hex');
        this.tx = [];
        return {
          t_ns: this.nowNs,
          pump: out.pump,
          led: out.led,
          vent_open: out.ventOpen,
          steps: out.steps,
          stepper_enabled: out.stepperEnabled,
          tx,
          resets: this.resets.slice(resetsBefore),
        };
      }
      case 'hang':
        this.hung = true;
        return { ok: true };
      case 'report': {
        this.collectTickStats();
        const device = this.usb.device;
        const pump = this.board.pump;
        return {
          t_ns: this.nowNs,
          ticks: this.ticks,
          longest_tick_ns: this.longestTickNs,
          max_tick_latency_ns: this.board.maxTickLatencyNs(),
          resets: this.resets,
          usb: {
            vid: device ? device.vid : null,
            pid: device ? device.pid : null,
            serial: device ? device.serial : null,
            configured: this.usb.configured,
            dtr: this.usb.dtr,
            interfaces: device && device.config ? device.config.interfaces : [],
            ...this.usb.stats,
          },
          pump_pwm: {
            rising_edges: pump.risingEdges,
            min_period_ns: Number.isFinite(pump.minPeriodNs) ? pump.minPeriodNs : null,
            off_grid_periods: pump.offGridPeriods(),
          },
          steps_total: this.board.stepsTotal,
          steps_while_disabled: this.board.stepsWhileDisabled,
          hx711: { conversions: this.board.hx711.conversions, reads: this.board.hx711.reads },
          adc_conversions: this.board.adcConversions,
          emulator_warnings: this.logger.warnings,
        };
      }
      default:
        throw new Error(`unknown op ${JSON.stringify(msg.op)}`);
    }
  }
}

function main() {
  let emulator;
  try {
    emulator = new Emulator(parseArgs(process.argv.slice(2)));
  } catch (e) {
    process.stderr.write(`emulator: ${e.message}\n`);
    process.exit(2);
  }
  process.stdout.write(JSON.stringify({ ready: true, rp2040js: '1.4.1' }) + '\n');
  const lines = readline.createInterface({ input: process.stdin, crlfDelay: Infinity });
  lines.on('line', (line) => {
    let reply;
    try {
      reply = emulator.handle(JSON.parse(line));
    } catch (e) {
      reply = { error: e.message };
    }
    process.stdout.write(JSON.stringify(reply) + '\n');
  });
  lines.on('close', () => process.exit(0));
}

main();
