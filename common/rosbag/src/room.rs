//! The room a bag needs to end, kept free while it is written: a bag whose disk fills up still
//! gets its last chunk, its summary and footer (an MCAP file is read through them) and
//! metadata.yaml.
//!
//! The MCAP file is written through [`Spool`], which keeps a sibling file of zeros as large as
//! what ending the bag can take (two chunks, and the summary so far). When the file system is
//! full, the reserve is given back and the write goes on into the room it leaves; the bag then
//! reports the full disk at the end of the tick (naming the file and the free space, as the
//! telemetry file does), so the run stops there and the bag is ended in that room.

use std::fs::{File, OpenOptions};
use std::io::{self, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use cdm_files::{describe, is_disk_full};

/// The MCAP writer's chunk size (its default, 1 MiB): the most a single chunk writes at once.
const CHUNK_BYTES: u64 = mcap::WriteOptions::DEFAULT_CHUNK_SIZE;

/// How much is kept free for a bag of `channels` channels whose file is `len` bytes long: the
/// chunk being written and the last one, each channel's schema and channel records and its
/// statistics, and a chunk index per chunk (with a message index offset per channel).
fn reserve_for(channels: u64, len: u64) -> u64 {
    let chunks = len / CHUNK_BYTES + 2;
    2 * CHUNK_BYTES + (64 << 10) + 512 * channels + chunks * (128 + 16 * channels)
}

/// The reserve: a sibling file of zeros, shared by the file's [`Spool`] and the bag.
pub struct Room(Mutex<Reserve>);

struct Reserve {
    /// The file and its length; `None` once given back.
    file: Option<(File, u64)>,
    path: PathBuf,
    /// The full disk met, naming the bag's file and the free space then.
    full: Option<String>,
}

impl Room {
    /// The reserve's path beside the bag's file `path` (`.NAME.reserve`; a bag whose run was
    /// killed may have left one behind).
    pub fn path_for(path: &Path) -> PathBuf {
        let name = path
            .file_name()
            .map_or_else(|| "bag".into(), |n| n.to_string_lossy().into_owned());
        path.with_file_name(format!(".{name}.reserve"))
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Reserve> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The full disk met so far (the file and the free space then), if any.
    pub fn full(&self) -> Option<String> {
        self.lock().full.clone()
    }

    /// Gives the reserve back: before ending the bag, or when the disk is full.
    pub fn give_back(&self) {
        let mut r = self.lock();
        if r.file.take().is_some() {
            let _ = std::fs::remove_file(&r.path);
        }
    }

    /// Records a full disk (or another error of the reserve) met writing `bag` and gives the
    /// reserve back.
    fn met_full(&self, bag: &Path, e: &io::Error) {
        let mut r = self.lock();
        if r.full.is_none() {
            r.full = Some(format!("{}: {}", bag.display(), describe(bag, e)));
        }
        if r.file.take().is_some() {
            let _ = std::fs::remove_file(&r.path);
        }
    }

    fn held(&self) -> bool {
        self.lock().file.is_some()
    }

    /// Grows the reserve to `want` bytes. A reserve that cannot grow (a full disk, or any other
    /// error) is given back and the bag stops at the end of the tick (see [`Room::full`]): the
    /// write that asked has already reached the file, so this never fails it.
    fn grow(&self, bag: &Path, want: u64) {
        let zeros = [0u8; 64 << 10];
        loop {
            let mut r = self.lock();
            let Some((f, size)) = r.file.as_mut() else {
                return;
            };
            if *size >= want {
                return;
            }
            let n = (want - *size).min(zeros.len() as u64) as usize;
            let e = match f.write(&zeros[..n]) {
                Ok(0) => io::ErrorKind::WriteZero.into(),
                Ok(k) => {
                    *size += k as u64;
                    continue;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => e,
            };
            drop(r);
            self.met_full(bag, &e);
            return;
        }
    }
}

/// The MCAP file, written with room kept for its end.
pub struct Spool {
    file: File,
    path: PathBuf,
    room: Arc<Room>,
    channels: u64,
    /// Bytes written so far (an overwrite after a seek counts again: the reserve only grows
    /// the more for it).
    written: u64,
}

impl Spool {
    /// Creates `path` and its reserve for a bag of `channels` channels. A disk without room
    /// for the reserve is full: the file is removed again.
    pub fn create(path: &Path, channels: usize) -> io::Result<(Self, Arc<Room>)> {
        let file = File::create(path)?;
        let reserve_path = Room::path_for(path);
        let reserve = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(&reserve_path)?;
        let room = Arc::new(Room(Mutex::new(Reserve {
            file: Some((reserve, 0)),
            path: reserve_path,
            full: None,
        })));
        let channels = channels as u64;
        room.grow(path, reserve_for(channels, 0));
        if let Some(e) = room.full() {
            let _ = std::fs::remove_file(path);
            return Err(io::Error::new(io::ErrorKind::StorageFull, e));
        }
        let spool = Spool {
            file,
            path: path.to_path_buf(),
            room: room.clone(),
            channels,
            written: 0,
        };
        Ok((spool, room))
    }

    /// The file itself (to sync it once ended).
    pub fn file(&self) -> &File {
        &self.file
    }
}

impl Write for Spool {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        loop {
            match self.file.write(buf) {
                Ok(n) => {
                    self.written += n as u64;
                    self.room
                        .grow(&self.path, reserve_for(self.channels, self.written));
                    return Ok(n);
                }
                // The room kept for the end: given back, the write goes on into it.
                Err(e) if is_disk_full(&e) && self.room.held() => {
                    self.room.met_full(&self.path, &e)
                }
                Err(e) => return Err(e),
            }
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl Seek for Spool {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.file.seek(pos)
    }
}

impl Drop for Room {
    fn drop(&mut self) {
        self.give_back();
    }
}
