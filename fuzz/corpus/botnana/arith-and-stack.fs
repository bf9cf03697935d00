1 2 + . 3 dup * . 10 3 mod . -7 2 / . .s
5 1 do i . loop cr
