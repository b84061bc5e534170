//! [`McapFile`]: an MCAP file receiving every message logged on a [`Telemetry`] while it is open.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use foxglove::{McapWriteOptions, McapWriterHandle};

use crate::{Telemetry, TelemetryError};

/// An MCAP file being written (chunked, uncompressed). The messages of a chunk are in memory
/// until the chunk is written: [`McapFile::tick`] writes it out at least every
/// [`McapFile::FLUSH_EVERY`], so a writer killed mid-run leaves a file whose complete chunks
/// the MCAP readers recover (all but the last `FLUSH_EVERY` or so; no summary section, which
/// `mcap recover` or a streaming reader does without).
pub struct McapFile {
    handle: McapWriterHandle<BufWriter<File>>,
    path: PathBuf,
    last_flush: Instant,
}

impl std::fmt::Debug for McapFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapFile")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl McapFile {
    /// The longest a message waits in memory before it is written to the file.
    pub const FLUSH_EVERY: Duration = Duration::from_millis(250);

    /// Creates (truncates) the file and attaches it to `telemetry`'s channels; `metadata` (the
    /// CSV's `# key = value` lines) becomes the MCAP metadata record `recording`.
    pub fn create(
        telemetry: &Telemetry,
        path: &Path,
        metadata: &[(String, String)],
    ) -> Result<Self, TelemetryError> {
        let err = |source| TelemetryError::Mcap {
            path: path.display().to_string(),
            source,
        };
        let file = File::create(path).map_err(|e| err(e.into()))?;
        let options = McapWriteOptions::new()
            .compression(None)
            .chunk_size(Some(256 * 1024));
        let handle = telemetry
            .context()
            .mcap_writer_with_options(options)
            .create(BufWriter::new(file))
            .map_err(err)?;
        let meta: BTreeMap<String, String> = metadata.iter().cloned().collect();
        handle.write_metadata("recording", meta).map_err(err)?;
        handle.flush().map_err(err)?;
        Ok(Self {
            handle,
            path: path.to_path_buf(),
            last_flush: Instant::now(),
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes the pending chunk out if it is older than [`Self::FLUSH_EVERY`].
    pub fn tick(&mut self) -> Result<(), TelemetryError> {
        if self.last_flush.elapsed() < Self::FLUSH_EVERY {
            return Ok(());
        }
        self.last_flush = Instant::now();
        self.handle.flush().map_err(|source| TelemetryError::Mcap {
            path: self.path.display().to_string(),
            source,
        })
    }

    /// Detaches the file and writes its summary and footer.
    pub fn finish(self) -> Result<(), TelemetryError> {
        let path = self.path.display().to_string();
        self.handle
            .close()
            .map(drop)
            .map_err(|source| TelemetryError::Mcap { path, source })
    }
}
