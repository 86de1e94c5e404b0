//! USB CDC-ACM link: the device (pid.codes test VID:PID 1209:7AC7), request decoding with
//! `protocol::FrameDecoder`, and transmission of replies (first) and unsolicited messages
//! (fault reports, sample blocks), framed with `protocol::encode_frame` and packed into
//! 64-byte packets.

use embassy_executor::Spawner;
use embassy_futures::select::{Either, select};
use embassy_rp::Peri;
use embassy_rp::bind_interrupts;
use embassy_rp::peripherals::USB;
use embassy_rp::usb::{Driver, InterruptHandler};
use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
use embassy_sync::channel::Channel;
use embassy_time::{Duration, Instant, Timer};
use embassy_usb::class::cdc_acm::{CdcAcmClass, Receiver, Sender, State};
use embassy_usb::driver::EndpointError;
use embassy_usb::{Builder, Config, UsbDevice};
use heapless::String;
use protocol::{DeviceMessage, FrameDecoder, MAX_FRAME_LEN, RequestFrame, encode_frame};
use static_cell::StaticCell;

use crate::shared::with_controller;

bind_interrupts!(struct Irqs {
    USBCTRL_IRQ => InterruptHandler<USB>;
});

type UsbDriver = Driver<'static, USB>;

/// pid.codes VID for open-source projects and a PID from its test range.
pub const USB_VID: u16 = 0x1209;
pub const USB_PID: u16 = 0x7AC7;
const PACKET_SIZE: u16 = 64;
/// How often the transmitter looks for sample blocks when no reply is waiting.
const POLL_PERIOD: Duration = Duration::from_millis(1);

/// Replies produced by the receiver, sent before any streamed data.
static REPLIES: Channel<ThreadModeRawMutex, DeviceMessage, 2> = Channel::new();

/// Builds the USB device and spawns its tasks.
pub fn start(spawner: &Spawner, usb: Peri<'static, USB>, serial: String<16>) {
    static SERIAL: StaticCell<String<16>> = StaticCell::new();
    static CONFIG_DESCRIPTOR: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESCRIPTOR: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL_BUF: StaticCell<[u8; 64]> = StaticCell::new();
    static STATE: StaticCell<State> = StaticCell::new();

    let serial = SERIAL.init(serial);
    let mut config = Config::new(USB_VID, USB_PID);
    config.manufacturer = Some("Video-tactile sensor project");
    config.product = Some("Tactile sensor controller");
    config.serial_number = Some(serial.as_str());
    config.max_power = 100;
    config.max_packet_size_0 = 64;

    let mut builder = Builder::new(
        Driver::new(usb, Irqs),
        config,
        CONFIG_DESCRIPTOR.init([0; 256]),
        BOS_DESCRIPTOR.init([0; 256]),
        &mut [],
        CONTROL_BUF.init([0; 64]),
    );
    let class = CdcAcmClass::new(&mut builder, STATE.init(State::new()), PACKET_SIZE);
    let device = builder.build();
    let (sender, receiver) = class.split();

    spawner.spawn(usb_device_task(device).expect("spawned once"));
    spawner.spawn(rx_task(receiver).expect("spawned once"));
    spawner.spawn(tx_task(sender).expect("spawned once"));
}

#[embassy_executor::task]
async fn usb_device_task(mut device: UsbDevice<'static, UsbDriver>) -> ! {
    device.run().await
}

/// Decodes requests and answers each one through the controller.
#[embassy_executor::task]
async fn rx_task(mut receiver: Receiver<'static, UsbDriver>) {
    let mut decoder = FrameDecoder::<RequestFrame>::new();
    let mut packet = [0u8; PACKET_SIZE as usize];
    loop {
        receiver.wait_connection().await;
        decoder.reset();
        defmt::info!("host connected");
        loop {
            let n = match receiver.read_packet(&mut packet).await {
                Ok(n) => n,
                Err(EndpointError::Disabled) => break,
                Err(EndpointError::BufferOverflow) => continue,
            };
            for &byte in &packet[..n] {
                match decoder.push_byte(byte) {
                    None => {}
                    Some(Ok(frame)) => {
                        let now = Instant::now().as_micros();
                        let reply = with_controller(|c| c.handle(&frame, now));
                        REPLIES.send(reply).await;
                    }
                    Some(Err(error)) => {
                        defmt::debug!("bad frame: {}", error);
                        with_controller(|c| c.note_rx_error());
                    }
                }
            }
        }
        defmt::info!("host disconnected");
    }
}

/// Packs frames into full-size USB packets.
struct PacketWriter {
    buf: [u8; PACKET_SIZE as usize],
    len: usize,
}

impl PacketWriter {
    async fn write_frame(
        &mut self,
        sender: &mut Sender<'static, UsbDriver>,
        message: &DeviceMessage,
    ) -> Result<(), EndpointError> {
        let mut frame = [0u8; MAX_FRAME_LEN];
        let n = match encode_frame(message, &mut frame) {
            Ok(n) => n,
            Err(error) => {
                // Cannot happen for the controller's messages (tested on the host); never
                // send a truncated frame.
                defmt::error!("cannot frame a message: {}", error);
                return Ok(());
            }
        };
        let mut rest = &frame[..n];
        while !rest.is_empty() {
            let take = rest.len().min(self.buf.len() - self.len);
            self.buf[self.len..self.len + take].copy_from_slice(&rest[..take]);
            self.len += take;
            rest = &rest[take..];
            if self.len == self.buf.len() {
                self.flush(sender).await?;
            }
        }
        Ok(())
    }

    async fn flush(
        &mut self,
        sender: &mut Sender<'static, UsbDriver>,
    ) -> Result<(), EndpointError> {
        if self.len > 0 {
            let len = core::mem::take(&mut self.len);
            sender.write_packet(&self.buf[..len]).await?;
        }
        Ok(())
    }
}

/// Sends replies as they come and, while the host has the port open (DTR), the
/// controller's fault reports and sample blocks.
#[embassy_executor::task]
async fn tx_task(mut sender: Sender<'static, UsbDriver>) {
    let mut writer = PacketWriter {
        buf: [0; PACKET_SIZE as usize],
        len: 0,
    };
    loop {
        sender.wait_connection().await;
        writer.len = 0;
        if let Err(EndpointError::Disabled) = serve(&mut sender, &mut writer).await {
            continue;
        }
    }
}

async fn serve(
    sender: &mut Sender<'static, UsbDriver>,
    writer: &mut PacketWriter,
) -> Result<(), EndpointError> {
    loop {
        if let Either::First(reply) = select(REPLIES.receive(), Timer::after(POLL_PERIOD)).await {
            writer.write_frame(sender, &reply).await?;
        }
        while let Ok(reply) = REPLIES.try_receive() {
            writer.write_frame(sender, &reply).await?;
        }
        if sender.dtr() {
            while let Some(message) = with_controller(|c| c.poll_outgoing()) {
                writer.write_frame(sender, &message).await?;
                // A reply that arrived meanwhile overtakes the remaining blocks.
                while let Ok(reply) = REPLIES.try_receive() {
                    writer.write_frame(sender, &reply).await?;
                }
            }
        }
        writer.flush(sender).await?;
    }
}
