/**
 * @file ordered_work_pool.h
 * @brief Computes items 0, 1, 2, ... on worker threads and hands them to one consumer in index order, with at most
 * a fixed number of items computed ahead of the consumer (bounded memory).
 *
 * The dive simulator renders frames this way: frames are independent of each other, but the bag must receive them
 * in order, between the navigation records of their time. Results are the same as a sequential loop's as long as
 * work(k) depends on k alone.
 */
#pragma once

#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>

namespace exocet_common {

template <typename Result>
class OrderedWorkPool {
 public:
  /**
   * @param count number of items (indices 0..count-1)
   * @param threads worker threads (>= 1)
   * @param ahead most items computed or being computed that the consumer has not taken yet (>= threads)
   * @param work computes item k; called concurrently on the workers, so it must be safe to call for different k at
   *        once. An exception it throws is rethrown by take(k).
   */
  OrderedWorkPool(int count, int threads, int ahead, std::function<Result(int)> work)
      : count_(count), ahead_(ahead), work_(std::move(work)), slots_(static_cast<size_t>(ahead)) {
    if (count < 0 || threads < 1 || ahead < threads)
      throw std::invalid_argument("OrderedWorkPool: needs count >= 0, threads >= 1 and ahead >= threads");
    workers_.reserve(static_cast<size_t>(threads));
    for (int i = 0; i < threads; ++i) workers_.emplace_back([this] { workerLoop(); });
  }

  /// Stops the workers after the items they are computing (items not taken are discarded) and joins them.
  ~OrderedWorkPool() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    changed_.notify_all();
    for (std::thread& t : workers_) t.join();
  }

  OrderedWorkPool(const OrderedWorkPool&) = delete;
  OrderedWorkPool& operator=(const OrderedWorkPool&) = delete;

  /**
   * @brief Waits for item `k` and returns it. Items are taken in order: k must be 0 on the first call, then the
   * previous k + 1 (std::logic_error otherwise).
   */
  Result take(int k) {
    std::unique_lock<std::mutex> lock(mutex_);
    if (k != taken_ || k >= count_) throw std::logic_error("OrderedWorkPool::take: items are taken once, in order");
    Slot& slot = slots_[static_cast<size_t>(k % ahead_)];
    changed_.wait(lock, [&] { return slot.done; });
    slot.done = false;
    ++taken_;
    std::exception_ptr error = slot.error;
    std::optional<Result> result = std::move(slot.result);
    slot.error = nullptr;
    slot.result.reset();
    lock.unlock();
    changed_.notify_all();  // a slot is free: a worker may start item k + ahead
    if (error) std::rethrow_exception(error);
    return std::move(*result);
  }

 private:
  struct Slot {
    bool done = false;
    std::optional<Result> result;
    std::exception_ptr error;
  };

  void workerLoop() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      changed_.wait(lock, [&] { return stopping_ || (next_ < count_ && next_ < taken_ + ahead_); });
      if (stopping_) return;
      const int k = next_++;
      lock.unlock();
      std::optional<Result> result;
      std::exception_ptr error;
      try {
        result.emplace(work_(k));
      } catch (...) {
        error = std::current_exception();
      }
      lock.lock();
      // Slot k % ahead is free: item k - ahead was taken, or next_ could not have reached k.
      Slot& slot = slots_[static_cast<size_t>(k % ahead_)];
      slot.result = std::move(result);
      slot.error = error;
      slot.done = true;
      changed_.notify_all();
    }
  }

  const int count_;
  const int ahead_;
  const std::function<Result(int)> work_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<Slot> slots_;
  int next_ = 0;   ///< next item a worker starts
  int taken_ = 0;  ///< items the consumer has taken
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

}  // namespace exocet_common
