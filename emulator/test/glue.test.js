// Unit tests of the emulator glue that do not need a firmware image: `node --test emulator/test`.

import assert from 'node:assert/strict';
import test from 'node:test';

import { Rng } from '../src/board.js';
import { ElfError, loadElfIntoFlash } from '../src/elf.js';
import { parseConfiguration } from '../src/usb-host.js';

/** A minimal ELF32 ARM image with one PT_LOAD segment of `payload` at `paddr`. */
function elf(payload, paddr) {
  const phoff = 52;
  const offset = phoff + 32;
  const bytes = new Uint8Array(offset + payload.length);
  const v = new DataView(bytes.buffer);
  v.setUint32(0, 0x7f454c46, false);
  bytes[4] = 1; // 32-bit
  bytes[5] = 1; // little-endian
  v.setUint16(18, 40, true); // EM_ARM
  v.setUint32(28, phoff, true);
  v.setUint16(42, 32, true);
  v.setUint16(44, 1, true);
  v.setUint32(phoff, 1, true); // PT_LOAD
  v.setUint32(phoff + 4, offset, true);
  v.setUint32(phoff + 12, paddr, true);
  v.setUint32(phoff + 16, payload.length, true);
  bytes.set(payload, offset);
  return bytes;
}

test('loads a flash segment at its load address', () => {
  const flash = new Uint8Array(0x1000).fill(0xff);
  const n = loadElfIntoFlash(elf(Uint8Array.from([1, 2, 3]), 0x10000100), flash);
  assert.equal(n, 3);
  assert.deepEqual(Array.from(flash.subarray(0x100, 0x103)), [1, 2, 3]);
  assert.equal(flash[0x103], 0xff);
});

test('refuses what is not a flash image', () => {
  const flash = new Uint8Array(0x1000);
  assert.throws(() => loadElfIntoFlash(Uint8Array.from([1, 2, 3]), flash), ElfError);
  // A RAM-only segment leaves nothing to put in flash.
  assert.throws(() => loadElfIntoFlash(elf(Uint8Array.from([1]), 0x20000000), flash), ElfError);
  // A segment that claims more bytes than the file has.
  const short = elf(Uint8Array.from([1, 2, 3, 4]), 0x10000000).subarray(0, 86);
  assert.throws(() => loadElfIntoFlash(short, flash), ElfError);
});

test('finds the CDC interfaces and bulk endpoints', () => {
  // configuration, CDC comm interface 0 (+ interrupt EP 0x81), CDC data interface 1 with
  // bulk OUT 0x02 and bulk IN 0x82 (embassy-usb's layout)
  const desc = Uint8Array.from([
    9, 2, 67, 0, 2, 1, 0, 0x80, 50,
    9, 4, 0, 0, 1, 2, 2, 0, 0,
    7, 5, 0x81, 3, 8, 0, 255,
    9, 4, 1, 0, 2, 10, 0, 0, 0,
    7, 5, 0x02, 2, 64, 0, 0,
    7, 5, 0x82, 2, 64, 0, 0,
  ]);
  const c = parseConfiguration(desc);
  assert.equal(c.commInterface, 0);
  assert.equal(c.bulkOut, 2);
  assert.equal(c.bulkIn, 2);
  assert.equal(c.interfaces.length, 2);
});

test('a truncated descriptor set stops the parse', () => {
  const c = parseConfiguration(Uint8Array.from([9, 2, 67, 0, 2, 1, 0, 0x80, 50, 9, 4, 0]));
  assert.equal(c.commInterface, -1);
  assert.equal(c.bulkIn, -1);
});

test('the ADC noise is reproducible for a seed and has the asked spread', () => {
  const a = new Rng(7);
  const b = new Rng(7);
  const xs = Array.from({ length: 20000 }, () => a.normal(1.5));
  assert.deepEqual(
    xs.slice(0, 5),
    Array.from({ length: 5 }, () => b.normal(1.5)),
  );
  const mean = xs.reduce((s, x) => s + x, 0) / xs.length;
  const sd = Math.sqrt(xs.reduce((s, x) => s + (x - mean) ** 2, 0) / xs.length);
  // 20 000 draws: the standard error of the mean is 0.011, of the sd about 0.0075.
  assert.ok(Math.abs(mean) < 0.05, `mean ${mean}`);
  assert.ok(Math.abs(sd - 1.5) < 0.04, `sd ${sd}`);
});
