// One emulated RP2040 (rp2040js) with the firmware image in flash and the small fixes the
// firmware needs from the emulator (each documented in docs/firmware-emulation.md):
// - an XIP_CTRL block (embassy-rp's flash code waits for STREAM_CTR to read 0);
// - SEV sets the event register (rp2040js only logs it, so a task woken from thread mode
//   waited in WFE for the next interrupt);
// - the flash's unique-ID command (0x4B) answered through the SSI;
// - a VREG_AND_CHIP_RESET block (the boot ROM reads CHIP_RESET);
// - a watchdog timeout or trigger requests a chip reset (handled by the caller).

import { BasePeripheral, RP2040 } from 'rp2040js';

const XIP_CTRL_KEY = (0x14000000 >>> 14) << 2;
const XIP_CTRL = 0x00;
const XIP_STAT = 0x08;
const XIP_STAT_FIFO_EMPTY = 1 << 1;
const XIP_STAT_FLUSH_READY = 1 << 0;

const SSI_CTRLR0 = 0x00;
const SSI_SSIENR = 0x08;
const SSI_DR0 = 0x60;
const SSI_TMOD_EEPROM_READ = 3;
const FLASH_CMD_READ_UNIQUE_ID = 0x4b;

const VREG_AND_CHIP_RESET_KEY = (0x40064000 >>> 14) << 2;
const VREG = 0x00;
const BOD = 0x04;
const CHIP_RESET = 0x08;
const CHIP_RESET_HAD_POR = 1 << 8;

const WATCHDOG_KEY = (0x40058000 >>> 14) << 2;
const WATCHDOG_LOAD = 0x04;

/** A register block that exists on silicon but not in rp2040js: XIP cache control. */
class XipCtrl extends BasePeripheral {
  constructor(rp, name) {
    super(rp, name);
    this.ctrl = 0x3; // EN | ERR_BADWRITE, the reset value
  }
  readUint32(offset) {
    if (offset === XIP_CTRL) return this.ctrl;
    if (offset === XIP_STAT) return XIP_STAT_FIFO_EMPTY | XIP_STAT_FLUSH_READY;
    return 0; // FLUSH, CTR_HIT, CTR_ACC, STREAM_ADDR, STREAM_CTR (no stream running), FIFO
  }
  writeUint32(offset, value) {
    if (offset === XIP_CTRL) this.ctrl = value & 0xb;
  }
}

/**
 * The voltage regulator and chip-reset block, which rp2040js leaves unimplemented (reads
 * 0xffffffff). The boot ROM reads CHIP_RESET first: PSM_RESTART_FLAG set means "a debugger
 * asked for a restart" and parks the core, so it must read as after power-on (HAD_POR).
 */
class VregAndChipReset extends BasePeripheral {
  constructor(rp, name) {
    super(rp, name);
    this.vreg = 0xb1; // 1.10 V, enabled (reset value)
    this.bod = 0x91;
  }
  readUint32(offset) {
    if (offset === VREG) return this.vreg;
    if (offset === BOD) return this.bod;
    if (offset === CHIP_RESET) return CHIP_RESET_HAD_POR;
    return 0;
  }
  writeUint32(offset, value) {
    if (offset === VREG) this.vreg = value & 0xf3;
    if (offset === BOD) this.bod = value & 0xf1;
  }
}

/** A logger that drops rp2040js's chatter, keeps warnings countable, and feeds SEV. */
class ChipLogger {
  constructor(onSev, verbose) {
    this.onSev = onSev;
    this.verbose = verbose;
    this.warnings = 0;
  }
  debug() {}
  info(component, message) {
    // rp2040js's only trace of an executed SEV instruction.
    if (message === 'SEV') this.onSev();
  }
  warn(component, message) {
    this.warnings++;
    if (this.verbose) process.stderr.write(`emulator: ${component}: ${message}\n`);
  }
  error(component, message) {
    this.warnings++;
    process.stderr.write(`emulator: ${component}: ${message}\n`);
  }
}

/**
 * Builds a chip. `image` is the 16 MiB flash content; `resetReason` the watchdog REASON
 * value to present (0 at power-on, 1 = TIMER, 2 = FORCE); `scratch` the watchdog scratch
 * registers kept across a watchdog reset; `runBootrom` starts at the boot ROM's reset vector
 * instead of boot2 (the ROM then decides, e.g. to enter the USB bootloader).
 */
export function createChip({ bootrom, image, uniqueId, resetReason, scratch, runBootrom, verbose }) {
  const rp = new RP2040();
  const logger = new ChipLogger(() => {
    rp.core.eventRegistered = true;
  }, verbose);
  rp.logger = logger;
  rp.loadBootrom(bootrom);
  rp.flash.set(image);
  rp.peripherals[XIP_CTRL_KEY] = new XipCtrl(rp, 'XIP_CTRL');
  rp.peripherals[VREG_AND_CHIP_RESET_KEY] = new VregAndChipReset(rp, 'VREG_AND_CHIP_RESET');
  patchSsiUniqueId(rp, uniqueId);
  const watchdog = rp.peripherals[WATCHDOG_KEY];
  watchdog.reason = resetReason;
  if (scratch) watchdog.scratchData.set(scratch);
  if (!runBootrom) {
    rp.core.PC = 0x10000000;
  }
  return { rp, logger, watchdog };
}

/** Answers the unique-ID command: 4 dummy bytes, then the 8 ID bytes. */
function patchSsiUniqueId(rp, uniqueId) {
  const ssi = rp.peripherals[(0x18000000 >>> 14) << 2];
  const rx = [];
  let ctrlr0 = 0;
  const read = ssi.readUint32.bind(ssi);
  const write = ssi.writeUint32.bind(ssi);
  ssi.readUint32 = (offset) => {
    if (offset === SSI_DR0 && rx.length > 0) return rx.shift();
    return read(offset);
  };
  ssi.writeUint32 = (offset, value) => {
    if (offset === SSI_CTRLR0) ctrlr0 = value;
    if (offset === SSI_SSIENR && (value & 1) === 0) rx.length = 0;
    if (
      offset === SSI_DR0 &&
      ((ctrlr0 >> 8) & 3) === SSI_TMOD_EEPROM_READ &&
      (value & 0xff) === FLASH_CMD_READ_UNIQUE_ID
    ) {
      rx.length = 0;
      rx.push(0, 0, 0, 0, ...uniqueId);
    }
    write(offset, value);
  };
}

export { WATCHDOG_LOAD };
