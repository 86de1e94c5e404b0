//! A minimal reader of 32-bit little-endian ARM ELF files (the RP2040 firmware): the
//! PT_LOAD program headers placed at their physical (load) addresses, per the System V ABI
//! ELF specification (ELF header: e_phoff at 28, e_phentsize at 42, e_phnum at 44; program
//! header: p_type, p_offset, p_vaddr, p_paddr, p_filesz, p_memsz, p_flags, p_align).

/// A loadable piece of the image at its physical address.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LoadSegment {
    pub paddr: u32,
    pub data: Vec<u8>,
}

#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ElfError {
    #[error("not an ELF file (bad magic)")]
    BadMagic,
    #[error("ELF class {0} not supported: RP2040 firmware is 32-bit (class 1)")]
    Class(u8),
    #[error("ELF data encoding {0} not supported: RP2040 firmware is little-endian (1)")]
    Endian(u8),
    #[error("ELF machine {0} is not ARM (40)")]
    Machine(u16),
    #[error("ELF header truncated: {field} at byte {offset} beyond the file ({len} bytes)")]
    Truncated {
        field: &'static str,
        offset: usize,
        len: usize,
    },
    #[error("program header {index}: segment bytes {offset}..{end} beyond the file ({len} bytes)")]
    SegmentOutOfFile {
        index: usize,
        offset: usize,
        end: usize,
        len: usize,
    },
    #[error("program header size {0} is smaller than 32")]
    PhentSize(u16),
}

const PT_LOAD: u32 = 1;
const EM_ARM: u16 = 40;

fn u16_at(b: &[u8], off: usize, field: &'static str) -> Result<u16, ElfError> {
    b.get(off..off + 2)
        .map(|s| u16::from_le_bytes([s[0], s[1]]))
        .ok_or(ElfError::Truncated {
            field,
            offset: off,
            len: b.len(),
        })
}

fn u32_at(b: &[u8], off: usize, field: &'static str) -> Result<u32, ElfError> {
    b.get(off..off + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or(ElfError::Truncated {
            field,
            offset: off,
            len: b.len(),
        })
}

/// The PT_LOAD segments with file data (`p_filesz > 0`; .bss needs no bytes in flash).
pub fn load_segments(elf: &[u8]) -> Result<Vec<LoadSegment>, ElfError> {
    if !elf.starts_with(b"\x7fELF") {
        return Err(ElfError::BadMagic);
    }
    let class = *elf.get(4).ok_or(ElfError::BadMagic)?;
    if class != 1 {
        return Err(ElfError::Class(class));
    }
    let data = *elf.get(5).ok_or(ElfError::BadMagic)?;
    if data != 1 {
        return Err(ElfError::Endian(data));
    }
    let machine = u16_at(elf, 18, "e_machine")?;
    if machine != EM_ARM {
        return Err(ElfError::Machine(machine));
    }
    let phoff = u32_at(elf, 28, "e_phoff")? as usize;
    let phentsize = u16_at(elf, 42, "e_phentsize")?;
    let phnum = u16_at(elf, 44, "e_phnum")? as usize;
    if phnum > 0 && phentsize < 32 {
        return Err(ElfError::PhentSize(phentsize));
    }
    let mut segments = Vec::new();
    for index in 0..phnum {
        let ph = phoff + index * usize::from(phentsize);
        let p_type = u32_at(elf, ph, "p_type")?;
        if p_type != PT_LOAD {
            continue;
        }
        let offset = u32_at(elf, ph + 4, "p_offset")? as usize;
        let paddr = u32_at(elf, ph + 12, "p_paddr")?;
        let filesz = u32_at(elf, ph + 16, "p_filesz")? as usize;
        if filesz == 0 {
            continue;
        }
        let end = offset.saturating_add(filesz);
        let bytes = elf.get(offset..end).ok_or(ElfError::SegmentOutOfFile {
            index,
            offset,
            end,
            len: elf.len(),
        })?;
        segments.push(LoadSegment {
            paddr,
            data: bytes.to_vec(),
        });
    }
    Ok(segments)
}
