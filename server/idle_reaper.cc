#include "server/idle_reaper.h"

#include <optional>
#include <utility>

namespace tempokey::server {

void IdleReaper::Timer::Arm() {
  if (reaper_->timeout_.count() <= 0) return;
  Clock::time_point deadline = Clock::now() + reaper_->timeout_;
  {
    std::lock_guard lock(mu_);
    if (closed_ || fired_ > 0) return;
    armed_ = true;
    deadline_ = deadline;
    // An entry already queued (for an earlier deadline) requeues itself when it comes due.
    if (scheduled_) return;
    scheduled_ = true;
  }
  reaper_->Schedule(shared_from_this(), deadline);
}

void IdleReaper::Timer::Disarm() {
  std::lock_guard lock(mu_);
  armed_ = false;
}

void IdleReaper::Timer::Close() {
  std::unique_lock lock(mu_);
  closed_ = true;
  armed_ = false;
  if (firing_thread_ == std::this_thread::get_id()) return;  // closed by its own handler
  done_cv_.wait(lock, [&] { return !firing_; });
}

int IdleReaper::Timer::fired() const {
  std::lock_guard lock(mu_);
  return fired_;
}

IdleReaper::IdleReaper(std::chrono::milliseconds timeout) : timeout_(timeout) {
  if (timeout_.count() > 0) thread_ = std::thread([this] { Loop(); });
}

IdleReaper::~IdleReaper() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

std::shared_ptr<IdleReaper::Timer> IdleReaper::NewTimer(std::function<void()> on_idle) {
  return std::shared_ptr<Timer>(new Timer(this, std::move(on_idle)));
}

void IdleReaper::Schedule(const std::shared_ptr<Timer>& timer, Clock::time_point deadline) {
  {
    std::lock_guard lock(mu_);
    due_.emplace(deadline, timer);
  }
  wake_.notify_all();
}

void IdleReaper::Loop() {
  std::unique_lock lock(mu_);
  while (!stopping_) {
    if (due_.empty()) {
      wake_.wait(lock);
      continue;
    }
    const Clock::time_point next = due_.begin()->first;
    if (Clock::now() < next) {
      wake_.wait_until(lock, next);
      continue;
    }
    std::shared_ptr<Timer> timer = due_.begin()->second.lock();
    due_.erase(due_.begin());
    if (timer == nullptr) continue;  // the call is gone
    lock.unlock();
    bool fire = false;
    std::optional<Clock::time_point> later;
    {
      std::lock_guard timer_lock(timer->mu_);
      timer->scheduled_ = false;
      if (timer->armed_ && !timer->closed_) {
        if (Clock::now() >= timer->deadline_) {
          timer->armed_ = false;
          timer->firing_ = true;
          timer->firing_thread_ = std::this_thread::get_id();
          ++timer->fired_;
          fire = true;
        } else {
          later = timer->deadline_;  // re-armed since: look again then
          timer->scheduled_ = true;
        }
      }
    }
    if (fire) {
      timer->on_idle_();
      std::lock_guard timer_lock(timer->mu_);
      timer->firing_ = false;
      timer->firing_thread_ = std::thread::id();
      timer->done_cv_.notify_all();
    }
    lock.lock();
    if (later) due_.emplace(*later, timer);
  }
}

}  // namespace tempokey::server
