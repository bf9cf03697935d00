: sign dup 0< if drop -1 else 0= if 0 else 1 then then ;
-5 sign . 0 sign . 9 sign .
: count-down begin dup . 1- dup 0= until drop ;
3 count-down
: w begin dup 0> while 1- repeat ;
5 w .
