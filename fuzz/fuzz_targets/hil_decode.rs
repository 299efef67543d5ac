//! Fuzz the HIL link decoder: any byte stream must give packets or typed errors, never a panic,
//! both through the packet layer and through the target's whole link state machine (frame
//! assembly, sequence checks, replies).
#![no_main]

use hil_bridge::target::{Event, TargetInfo, TargetLink};
use hil_bridge::{Received, Receiver, decode_packet};
use libfuzzer_sys::fuzz_target;

/// A writer that accepts and forgets everything (the replies are not under test here).
struct Sink;
impl embedded_io::ErrorType for Sink {
    type Error = core::convert::Infallible;
}
impl embedded_io::Write for Sink {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

fuzz_target!(|data: &[u8]| {
    let _ = decode_packet(data);
    let mut rx = Receiver::new();
    for &b in data {
        if let Received::Packet(_, m) = rx.push(b) {
            let _ = format!("{m:?}");
        }
    }
    let mut heights = [0.0f32; 1024];
    let info = TargetInfo {
        tile_crc: 0,
        tile_features: 0,
        max_frame_width: 32,
        atlas_crc: 0,
        atlas_tiles: 0,
    };
    let mut link = TargetLink::new(info, &mut heights);
    let mut r: &[u8] = data;
    for _ in 0..64 {
        match link.poll(&mut r, &mut Sink) {
            Ok(Event::EndOfStream) | Err(_) => break,
            Ok(Event::Frame(f)) => {
                let px = f.header.width as usize * f.header.height as usize;
                assert_eq!(link.heights_m().len(), px);
            }
            Ok(Event::Shutdown) => {}
        }
    }
});
