//! The iceoryx2 service type of the chain's hot hops and its event ids: what the hop's
//! notifiers and listeners ([`crate::ports`]) are made on and what [`crate::hop`] waits for.

use iceoryx2::prelude::EventId;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use std::fmt::Debug;

/// The iceoryx2 service type of the hop events (the event mechanism of the hot path): iceoryx2's
/// `ipc::Service` with one concept exchanged, the event: a process-shared POSIX semaphore in the
/// event's shared-memory segment (`SemaphoreShmCountingBitSet`) instead of a Unix datagram
/// socket. A notification is then a `sem_post` (one `futex` wake when the listener sleeps, none
/// otherwise), the wait a `sem_wait`, and the drain a `sem_trywait` in user space, where the
/// socket event costs a `sendto` and a `recvfrom` (plus `epoll_wait` and `fcntl` in a WaitSet).
/// Everything else (samples, the other events) stays on `ipc::Service`.
#[derive(Debug, Clone)]
pub struct HopService {}

impl iceoryx2::service::Service for HopService {
    type StaticStorage = iceoryx2_cal::static_storage::recommended::Ipc;
    type ConfigSerializer = iceoryx2_cal::serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        iceoryx2_cal::dynamic_storage::recommended::PersistentIpc<T>;
    type Bag = iceoryx2_cal::bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        iceoryx2_cal::dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = iceoryx2_cal::hash::recommended::Recommended;
    type SharedMemory = iceoryx2_cal::shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory =
        iceoryx2_cal::resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = iceoryx2_cal::zero_copy_connection::recommended::Ipc;
    type Event = iceoryx2_cal::event::SemaphoreShmCountingBitSet;
    type Monitoring = iceoryx2_cal::monitoring::recommended::Ipc;
    type Reactor = iceoryx2_cal::reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> =
        iceoryx2_cal::arc_sync_policy::single_threaded::SingleThreaded<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        iceoryx2_cal::dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = iceoryx2_cal::shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<HopService> for HopService {}

/// The event of a new sample from upstream (the notifiers' default id).
pub const SAMPLE: EventId = EventId::new(0);
/// The stage's period tick (from its [`Ticker`]).
pub const TICK: EventId = EventId::new(1);
/// The stage's heartbeat time (from its [`Ticker`]).
pub const HEARTBEAT: EventId = EventId::new(2);
/// The largest event id a hop service carries.
pub const MAX_EVENT_ID: usize = 2;
