//! Messages Zenoh refuses for being over its receive limit (`transport/link/rx/max_message_size`,
//! which services set to `--max-message-mb` plus headroom): Zenoh drops their fragments before
//! they are buffered whole, and says so only in a trace-level event. A tracing layer filtered to
//! exactly that event counts them here (no other Zenoh event is enabled by it, so its cost is
//! nil elsewhere); `/metrics` shows the count as `conesight_zenoh_refused_messages_total`.
//!
//! The event is Zenoh 1.10's "Defragmentation buffer full" (`zenoh_transport`, unicast
//! universal rx, the `trace!` at line [`ZENOH_RX_LINE`]): one per refused message, as peers of
//! Zenoh 1.1 and later mark a message's first fragment and Zenoh skips the rest of a refused
//! one (a peer without the markers may count several times). The layer enables that one
//! callsite only, so Zenoh's per-message trace events stay off. `conesight-e2e`'s oversize test
//! fails if a Zenoh update moves the event.

use std::sync::atomic::{AtomicU64, Ordering};

use tracing::{Level, Metadata, Subscriber};
use tracing_subscriber::layer::{Context, Layer};

/// Where Zenoh reports a refused fragment chain.
const ZENOH_RX_TARGET: &str = "zenoh_transport::unicast::universal::rx";
/// The line of that `trace!` in zenoh-transport 1.10.2 (`src/unicast/universal/rx.rs`).
pub const ZENOH_RX_LINE: u32 = 192;

static REFUSED: AtomicU64 = AtomicU64::new(0);

/// Messages refused by Zenoh in this process so far.
pub fn refused_messages() -> u64 {
    REFUSED.load(Ordering::Relaxed)
}

/// True for the one Zenoh event this layer counts.
pub(crate) fn is_refusal_event(metadata: &Metadata<'_>) -> bool {
    metadata.is_event()
        && *metadata.level() == Level::TRACE
        && metadata.target() == ZENOH_RX_TARGET
        && metadata.line() == Some(ZENOH_RX_LINE)
}

/// The counting layer (install with a filter of [`is_refusal_event`]).
pub(crate) struct RefusalCounter;

impl<S: Subscriber> Layer<S> for RefusalCounter {
    fn on_event(&self, event: &tracing::Event<'_>, _ctx: Context<'_, S>) {
        let mut visitor = MessageStart::default();
        event.record(&mut visitor);
        if visitor.text.starts_with("Defragmentation buffer full") {
            REFUSED.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The first bytes of an event's message.
#[derive(Default)]
struct MessageStart {
    text: String,
}

impl tracing::field::Visit for MessageStart {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.text = format!("{value:?}");
        }
    }
}
