/* SPDX-License-Identifier: MIT */
/*
 * StaticVector: a vector with a compile-time capacity and inline storage.
 *
 * The frame path of dockpose never touches the heap; every container it uses
 * is one of these. Allocates: never. push_back() on a full vector returns
 * false and leaves the vector unchanged, so callers can count overflows
 * instead of crashing.
 */
#pragma once

#include <array>
#include <cassert>
#include <cstddef>

namespace dockpose {

template<typename T, std::size_t Capacity>
class StaticVector
{
public:
	using value_type = T;
	using iterator = T *;
	using const_iterator = const T *;

	static constexpr std::size_t capacity() { return Capacity; }

	std::size_t size() const { return size_; }
	bool empty() const { return size_ == 0; }
	bool full() const { return size_ == Capacity; }
	void clear() { size_ = 0; }

	/* Shrink to n elements (n <= size()). */
	void resize(std::size_t n)
	{
		assert(n <= Capacity);
		size_ = n;
	}

	bool push_back(const T &value)
	{
		if (size_ == Capacity)
			return false;
		items_[size_++] = value;
		return true;
	}

	void pop_back()
	{
		assert(size_ > 0);
		--size_;
	}

	T &operator[](std::size_t i)
	{
		assert(i < size_);
		return items_[i];
	}
	const T &operator[](std::size_t i) const
	{
		assert(i < size_);
		return items_[i];
	}

	T &back() { return items_[size_ - 1]; }
	const T &back() const { return items_[size_ - 1]; }

	T *data() { return items_.data(); }
	const T *data() const { return items_.data(); }
	iterator begin() { return items_.data(); }
	iterator end() { return items_.data() + size_; }
	const_iterator begin() const { return items_.data(); }
	const_iterator end() const { return items_.data() + size_; }

private:
	std::array<T, Capacity> items_{};
	std::size_t size_ = 0;
};

} /* namespace dockpose */
