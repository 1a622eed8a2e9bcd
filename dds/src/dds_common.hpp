// Internal to tetrig::dds: the QoS of the two topics and the participant, shared by the writer
// (frame_publisher.cpp) and the reader (frame_subscriber.cpp) so that both sides always match.
#pragma once

#include "tetrig/dds/frame_publisher.hpp"

#include <dds/dds.h>

#include <cstdint>
#include <string>

namespace tetrig::dds::detail {

// Owns a dds_qos_t.
class Qos {
 public:
  Qos() : q_(dds_create_qos()) {}
  ~Qos() { dds_delete_qos(q_); }
  Qos(const Qos&) = delete;
  Qos& operator=(const Qos&) = delete;
  [[nodiscard]] dds_qos_t* get() const noexcept { return q_; }

 private:
  dds_qos_t* q_;
};

// Live frames: best effort, volatile, keep last 1, automatic liveliness with the lease.
inline void setFrameQos(const Qos& qos, std::int64_t lease_ns) {
  dds_qset_reliability(qos.get(), DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_durability(qos.get(), DDS_DURABILITY_VOLATILE);
  dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, 1);
  dds_qset_liveliness(qos.get(), DDS_LIVELINESS_AUTOMATIC, lease_ns);
}

// Static data: reliable, transient local (kept by the writer for readers that come later), keep last 1.
inline void setStaticQos(const Qos& qos, std::int64_t lease_ns) {
  dds_qset_reliability(qos.get(), DDS_RELIABILITY_RELIABLE, DDS_MSECS(500));
  dds_qset_durability(qos.get(), DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, 1);
  dds_qset_liveliness(qos.get(), DDS_LIVELINESS_AUTOMATIC, lease_ns);
}

inline std::string retcodeText(dds_return_t rc) { return dds_strretcode(rc); }

// A participant in the options' domain; throws DdsError with `who` in the message.
inline dds_entity_t createParticipant(const DdsOptions& options, const std::string& who) {
  const dds_domainid_t domain = options.domain_id < 0 ? DDS_DOMAIN_DEFAULT : static_cast<dds_domainid_t>(options.domain_id);
  const dds_entity_t participant = dds_create_participant(domain, nullptr, nullptr);
  if (participant < 0)
    throw DdsError(who + ": cannot create a DDS participant (" + retcodeText(participant) +
                   "): check CYCLONEDDS_URI (docs/dds.md, \"Configuration\")");
  return participant;
}

}  // namespace tetrig::dds::detail
