// Cuts off HTTP requests whose body arrives too slowly. civetweb's timeout is per read, and its
// mg_read() waits until the whole block asked for has arrived, so a client sending a byte every
// few seconds held a worker thread for as long as it liked (every thread, with as many such
// clients: the page and the API stopped answering). A guard thread watches each body being read
// and, once one is late, shuts its connection's socket down (both ways; the descriptor stays
// civetweb's to close), which ends the blocked read with an error.
#ifndef TEMPOKEY_SERVER_HTTP_SLOW_BODY_GUARD_H_
#define TEMPOKEY_SERVER_HTTP_SLOW_BODY_GUARD_H_

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <thread>

namespace tempokey::server::http {

class SlowBodyGuard {
 public:
  using Clock = std::chrono::steady_clock;

  // Watches connections accepted on `local_port` (the front end's).
  explicit SlowBodyGuard(int local_port);
  // Stops the guard thread; watches still open are dropped.
  ~SlowBodyGuard();
  SlowBodyGuard(const SlowBodyGuard&) = delete;
  SlowBodyGuard& operator=(const SlowBodyGuard&) = delete;

  // A body being read, from the peer `remote_address`:`remote_port` (IPv4, as civetweb reports
  // it): its connection is shut down at `deadline` unless the watch has ended by then.
  class Watch {
   public:
    Watch() = default;
    Watch(Watch&& other) noexcept { *this = std::move(other); }
    Watch& operator=(Watch&& other) noexcept;
    ~Watch() { End(); }
    // The body has been read (or the call is over): no cut-off from now on.
    void End();

   private:
    friend class SlowBodyGuard;
    Watch(SlowBodyGuard* guard, std::uint64_t id) : guard_(guard), id_(id) {}
    SlowBodyGuard* guard_ = nullptr;
    std::uint64_t id_ = 0;
  };
  Watch Start(const std::string& remote_address, int remote_port, Clock::time_point deadline);

  // How long a body may take: the I/O timeout, plus its length at kMinBytesPerSecond, at most
  // `max_bytes` counted (a body of unknown length counts as `max_bytes`).
  static Clock::duration Allowance(std::chrono::milliseconds io_timeout,
                                   std::int64_t content_length, std::int64_t max_bytes);
  static constexpr std::int64_t kMinBytesPerSecond = 64 * 1024;

  // Connections shut down so far.
  std::int64_t cut_off() const;

 private:
  struct Watched {
    std::string remote_address;
    int remote_port = 0;
    Clock::time_point deadline;
  };
  void End(std::uint64_t id);
  void Run();

  const int local_port_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::map<std::uint64_t, Watched> watched_;
  std::uint64_t next_id_ = 1;
  // The watch whose connection is being looked for and shut down, outside the lock (0: none):
  // its End() waits for the cut, so the descriptor cut is still that connection's.
  std::uint64_t cutting_ = 0;
  std::int64_t cut_off_ = 0;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace tempokey::server::http

#endif  // TEMPOKEY_SERVER_HTTP_SLOW_BODY_GUARD_H_
